"""Falls and reaches of `lhm eval` episodes (episodes.csv, first pair, unseen split) binned by the
first object's horizontal distance from the task's start. Run from the repository root:
python3 docs/runs/reach/eval28/falls_by_distance.py EPISODES.csv..."""
import collections
import csv
import math
import sys
import tomllib

with open("scenes/data/unseen.toml", "rb") as f:
    tasks = tomllib.load(f)["task"]
distance = {}
for t in tasks:
    first = t["step"][0]["object"]
    obj = next(o for o in t["object"] if o["id"] == first)
    (x, y), (sx, sy) = obj["pos"][:2], t["start"]["pos"]
    distance[t["id"] + ".p1"] = math.hypot(x - sx, y - sy)
for path in sys.argv[1:]:
    bins = collections.defaultdict(lambda: [0, 0, 0])
    for r in csv.DictReader(open(path)):
        b = bins[min(int(distance[r["task_id"]]), 4)]
        b[0] += 1
        b[1] += r["fell"] in ("1", "true", "True")
        b[2] += r["reach_step"] != ""
    print(path)
    for k, (n, fell, reached) in sorted(bins.items()):
        label = f"{k}-{k + 1} m" if k < 4 else "4+ m"
        print(f"  {label:>6}: {n:3} episodes, fell {fell:3} ({fell / n:.2f}), reached {reached:3}")
