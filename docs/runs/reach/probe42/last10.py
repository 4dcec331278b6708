"""Issue 12's training figures over the last 10 % of a run's iterations: python3 last10.py RUN/metrics.csv [FRACTION]

Episode-weighted falls, rest-start (task-start) falls, reach from rest starts and from all starts; mean disc accuracy
and style reward over the rows that have them (NaN where AMP was off), and how many rows had AMP on."""
import csv, math, sys

rows = list(csv.DictReader(open(sys.argv[1])))
frac = float(sys.argv[2]) if len(sys.argv) > 2 else 0.1
last = int(rows[-1]["iteration"])
tail = [r for r in rows if int(r["iteration"]) > last - frac * last]


def f(r, k):
    try:
        return float(r[k])
    except (KeyError, ValueError):
        return float("nan")


E = sum(f(r, "episodes") for r in tail) or 1
ew = lambda k: sum(f(r, k) * f(r, "episodes") for r in tail if not math.isnan(f(r, k))) / E
amp = [r for r in tail if not math.isnan(f(r, "disc_accuracy"))]
m = lambda k: sum(f(r, k) for r in amp) / len(amp) if amp else float("nan")
print(f"iterations {tail[0]['iteration']}-{last} ({len(tail)} rows, {len(amp)} with AMP on, {int(E)} episodes): "
      f"falls {ew('fall_fraction'):.3f}, rest-start falls {ew('task_start_fall_fraction'):.3f}, "
      f"reach from rest starts {ew('reach_rate'):.3f}, from all starts {ew('reach_rate_all'):.3f}, "
      f"disc accuracy {m('disc_accuracy'):.3f}, style {m('style_reward'):.3f}")
