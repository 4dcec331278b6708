"""Samples at which a run's discriminator accuracy (10-iteration moving average) first reaches 0.8, 0.85, 0.9, 0.93:
python3 docs/runs/reach/eval31/disc_crossing.py RUN/metrics.csv..."""
import csv
import sys

for path in sys.argv[1:]:
    rows = list(csv.DictReader(open(path)))
    acc = [float(r["disc_accuracy"]) for r in rows]
    samples = [float(r["samples"]) for r in rows]
    ma = [sum(acc[max(0, i - 9):i + 1]) / len(acc[max(0, i - 9):i + 1]) for i in range(len(acc))]
    out = []
    for threshold in (0.8, 0.85, 0.9, 0.93):
        hit = next((samples[i] for i in range(len(acc)) if ma[i] >= threshold), None)
        out.append(f"{threshold}: {hit / 1e6:.2f} M" if hit is not None else f"{threshold}: not reached")
    print(f"{path}: " + "; ".join(out))
