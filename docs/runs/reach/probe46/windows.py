"""Means of a run's AMP rows in windows of W iterations: python3 windows.py METRICS.csv W [COLUMN ...]

Columns default to the discriminator's accuracy (mean, demo side, agent side), its learning rate,
style reward, falls and reach from task starts; rows without a disc_accuracy (AMP off) are skipped."""
import csv, sys

rows = [r for r in csv.DictReader(open(sys.argv[1])) if r.get("disc_accuracy", "") not in ("", "NaN", "nan")]
w = int(sys.argv[2]) if len(sys.argv) > 2 else 50
ks = sys.argv[3:] or ["disc_accuracy", "disc_demo_accuracy", "disc_agent_accuracy", "disc_lr",
                      "style_reward", "fall_fraction", "reach_rate"]


def f(x, k):
    try:
        return float(x[k])
    except (KeyError, ValueError):
        return float("nan")


print("iterations".ljust(12), " ".join(k.replace("disc_", "d_")[:11].rjust(11) for k in ks))
for i in range(0, len(rows), w):
    c = rows[i:i + w]
    vals = []
    for k in ks:
        v = [y for y in (f(x, k) for x in c) if y == y]
        vals.append(sum(v) / len(v) if v else float("nan"))
    print(f"{c[0]['iteration']}-{c[-1]['iteration']}".ljust(12), " ".join(f"{v:11.4g}" for v in vals))
