"""Falls of the frozen x0.75 policy (probe59, 18,841) with the footfall-synchronised clock
(`[env.gait] sync_wait`, `sync_skip`), by `lhm eval` through probe61/gainscan.py's `evaluate`.

cd docs/runs/reach/probe61 && python3 ../probe62/syncscan.py WAIT,SKIP[,rest] ...
(walks from the task's start with the clip's momentum, `cfg-v075.toml`; `rest`: from rest)"""
import re
import sys

sys.path.insert(0, '.')
from gainscan import base, evaluate  # noqa: E402


def synced(text, wait, skip):
    text = re.sub(r'^sync_wait = \S+$', f'sync_wait = {wait}', text, flags=re.M)
    return re.sub(r'^sync_skip = \S+$', f'sync_skip = {skip}', text, flags=re.M)


if __name__ == '__main__':
    seeds = 2
    for arg in sys.argv[1:]:
        parts = arg.split(',')
        wait, skip, rest = int(parts[0]), int(parts[1]), 'rest' in parts[2:]
        evaluate(f"sync{wait}-{skip}{'-rest' if rest else ''}", synced(base, wait, skip), rest, seeds)
