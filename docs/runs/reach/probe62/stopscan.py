"""Falls of the frozen x0.75 policy (probe59, 18,841) with a stop ramp (`[env.gait.stop]`), by
`lhm eval` through probe61/gainscan.py's `evaluate`; every episode a walking start 1.2 m before the
object (`start_distance = 1.2`: the episodes are about the stop and the stand), or from rest.

cd docs/runs/reach/probe61 && python3 ../probe62/stopscan.py SECONDS,FEEDBACK[,rest] ..."""
import re
import sys

sys.path.insert(0, '.')
from gainscan import base, evaluate  # noqa: E402


def stopping(text, seconds, feedback, near=True):
    head, stop, tail = re.split(r'(?m)^(\[env\.gait\.stop\]\n(?:[a-z_]+ = \S+\n)+)', text, maxsplit=1)
    stop = re.sub(r'(?m)^seconds = \S+$', f'seconds = {seconds}', stop)
    stop = re.sub(r'(?m)^feedback = \S+$', f'feedback = {feedback}', stop)
    if near:
        head = re.sub(r'(?m)^start_distance = \S+$', 'start_distance = 1.2', head)
    return head + stop + tail


if __name__ == '__main__':
    for arg in sys.argv[1:]:
        parts = arg.split(',')
        seconds, feedback, rest = float(parts[0]), float(parts[1]), 'rest' in parts[2:]
        evaluate(f"stop{seconds}-{feedback}{'-rest' if rest else ''}",
                 stopping(base, seconds, feedback, near=not rest), rest)
