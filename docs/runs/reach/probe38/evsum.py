"""Summarise `lhm eval` episodes CSVs: episodes, mean steps, up (fell == 0), reached (reach_step set).

python3 docs/runs/reach/probe38/evsum.py DIR_OR_CSV...
"""
import csv
import glob
import os
import sys

for arg in sys.argv[1:]:
    paths = sorted(glob.glob(os.path.join(arg, "*.csv"))) if os.path.isdir(arg) else [arg]
    for path in paths:
        with open(path) as f:
            rows = list(csv.DictReader(f))
        if not rows or "steps" not in rows[0]:
            continue
        n = len(rows)
        steps = sum(float(r["steps"]) for r in rows) / n
        up = sum(r["fell"] == "0" for r in rows)
        reached = sum(r["reach_step"] != "" for r in rows)
        print(f"{path}: {n} episodes, {steps:.1f} steps, {up} up, {reached} reached")
