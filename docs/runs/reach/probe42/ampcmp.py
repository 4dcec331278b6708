"""Side-by-side windows of runs from one iteration on: python3 ampcmp.py W FROM name=RUN/metrics.csv ...

Per W-iteration window counted from iteration FROM (exclusive) in each run: samples since FROM, then per run
episode-weighted falls, rest-start (task-start) falls, reach from rest starts, and the mean disc accuracy and
style reward (forty-second session: the AMP stage of scratch-line-s1 and its fork, FROM = 12900)."""
import csv, sys

W, FROM = int(sys.argv[1]), int(sys.argv[2])
runs = []
for a in sys.argv[3:]:
    n, p = a.split("=", 1)
    runs.append((n, [r for r in csv.DictReader(open(p)) if int(r["iteration"]) > FROM]))


def f(r, k):
    try:
        return float(r[k])
    except (KeyError, ValueError):
        return float("nan")


print("since FROM | " + " | ".join(f"{n}: falls tsfall reach disc style" for n, _ in runs))
k = 0
while True:
    cells, any_ = [], False
    for n, rows in runs:
        ch = rows[k * W:(k + 1) * W]
        if len(ch) < W // 2:
            cells.append("-")
            continue
        any_ = True
        E = sum(f(r, "episodes") for r in ch) or 1
        ew = lambda c: sum(f(r, c) * f(r, "episodes") for r in ch if f(r, c) == f(r, c)) / E
        m = lambda c: sum(f(r, c) for r in ch) / len(ch)
        cells.append(f"{ew('fall_fraction'):.3f} {ew('task_start_fall_fraction'):.3f} {ew('reach_rate'):.3f} "
                     f"{m('disc_accuracy'):.3f} {m('style_reward'):.3f} ({len(ch)})")
    if not any_:
        break
    print(f"{(k + 1) * W * 4096 / 1e6:5.2f} M | " + " | ".join(cells))
    k += 1
