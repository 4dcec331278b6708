"""Falls of the frozen x0.75 policy from rest with the start ramp's ([env.gait.start]) entries scaled.

python3 rampscan.py NAME=SCALE ...  (`none=1`: unchanged). The stop ramp has the same names, so only the
start table is edited."""
import sys
from gainscan import base, scaled, evaluate

head, rest = base.split('[env.gait.start]\n', 1)
start, tail = rest.split('\n[env.gait.stop]', 1)

if __name__ == '__main__':
    for arg in sys.argv[1:]:
        g, sc = arg.split('=')
        mult = {g: float(sc)} if g != 'none' else {}
        evaluate(f'rest-{g}x{sc}', head + '[env.gait.start]\n' + scaled(start, mult) + '\n[env.gait.stop]' + tail, rest=True)
