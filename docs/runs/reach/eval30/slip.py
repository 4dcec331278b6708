"""Stance-foot slip and hip pitch range of a `fall_trace` CSV (after the first 30 walking steps of each
episode): python3 docs/runs/reach/eval30/slip.py TRACE.csv"""
import collections
import csv
import statistics as st
import sys

rows = list(csv.DictReader(open(sys.argv[1])))
eps = collections.OrderedDict()
for r in rows:
    eps.setdefault((r["task"], r["seed"]), []).append(r)
single, double, v, ref_v, none, total = [], [], [], [], 0, 0
for e in eps.values():
    for r in e[30:]:
        total += 1
        down = [r[f"slip_fwd_{i}"] != "" for i in (0, 1)]
        v.append(float(r["v_fwd"]))
        ref_v.append(float(r["ref_v_fwd"]))
        if down == [True, False] or down == [False, True]:
            i = down.index(True)
            single.append((float(r[f"slip_fwd_{i}"]), float(r[f"slip_lat_{i}"])))
        elif all(down):
            double += [float(r["slip_fwd_0"]), float(r["slip_fwd_1"])]
        else:
            none += 1
fwd = sorted(s[0] for s in single)
q = [round(fwd[int(p * len(fwd))], 3) for p in (0.1, 0.25, 0.5, 0.75, 0.9)]
print(f"episodes {len(eps)}, walking steps after the first 30: {total}")
print(f"COM forward velocity mean {st.mean(v):.3f} m/s, reference's {st.mean(ref_v):.3f}")
print(f"single support {len(single) / total:.2f} of steps: stance foot forward velocity mean {st.mean(fwd):.3f}, "
      f"quantiles 10/25/50/75/90 % {q}; |sideways| mean {st.mean(abs(s[1]) for s in single):.3f}")
print(f"double support {len(double) / 2 / total:.2f}: feet forward velocity median {st.median(double):.3f}; "
      f"no foot below the contact height {none / total:.2f}")
ranges, ref_ranges = [], []
for e in eps.values():
    if len(e) < 60:
        continue
    for i in (0, 1):
        h = [float(r[f"hip_y_{i}"]) for r in e[30:]]
        rh = [float(r[f"ref_hip_y_{i}"]) for r in e[30:]]
        ranges.append(max(h) - min(h))
        ref_ranges.append(max(rh) - min(rh))
print(f"hip pitch range per episode and leg (walks of >= 60 steps): median {st.median(ranges):.3f} rad, "
      f"reference's {st.median(ref_ranges):.3f}")
