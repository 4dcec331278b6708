"""Median right-leg hip pitch, knee and ankle pitch (rad) and forward centre-of-mass velocity (m/s) by step of the
gait cycle, the character's against the reference's, from a `fall_trace` CSV (walking steps after the first 30 of
each episode); `down`: share of rows with the right foot below the gait's contact height. Then the stance (foot down)
and touchdown/liftoff figures for both legs.
python3 docs/runs/reach/eval31/phase_profile.py TRACE.csv [CYCLE_STEPS=38]"""
import collections
import csv
import statistics as st
import sys

rows = list(csv.DictReader(open(sys.argv[1])))
cycle = int(sys.argv[2]) if len(sys.argv) > 2 else 38
eps = collections.OrderedDict()
for r in rows:
    eps.setdefault((r["task"], r["seed"]), []).append(r)
bins = collections.defaultdict(list)
for e in eps.values():
    for r in e[30:]:
        bins[round(float(r["phase"]) * cycle) % cycle].append(r)
print("step rows down  hip   ref    knee  ref    ankle ref    v_fwd ref")
for k in range(cycle):
    rs = bins[k]
    if not rs:
        continue
    m = lambda c: st.median(float(r[c]) for r in rs)
    down = sum(r["slip_fwd_0"] != "" for r in rs) / len(rs)
    print(f"{k:4d} {len(rs):4d} {down:4.2f} {m('hip_y_0'):6.2f} {m('ref_hip_y_0'):5.2f} {m('knee_0'):6.2f} "
          f"{m('ref_knee_0'):5.2f} {m('ankle_y_0'):6.2f} {m('ref_ankle_y_0'):5.2f} {m('v_fwd'):6.2f} {m('ref_v_fwd'):5.2f}")
stance_knee, ref_stance_knee, stance_len, hip_sweep, ref_hip_sweep = [], [], [], [], []
for e in eps.values():
    e = e[30:]
    for i in (0, 1):
        down = [r[f"slip_fwd_{i}"] != "" for r in e]
        j = 0
        while j < len(e):
            k = j
            while k < len(e) and down[k] == down[j]:
                k += 1
            if down[j] and 0 < j and k < len(e) and k - j >= 3:
                stance_len.append(k - j)
                stance_knee += [float(r[f"knee_{i}"]) for r in e[j:k]]
                ref_stance_knee += [float(r[f"ref_knee_{i}"]) for r in e[j:k]]
                hip_sweep.append(float(e[k - 1][f"hip_y_{i}"]) - float(e[j][f"hip_y_{i}"]))
                ref_hip_sweep.append(float(e[k - 1][f"ref_hip_y_{i}"]) - float(e[j][f"ref_hip_y_{i}"]))
            j = k
print(f"stances {len(stance_len)}: median {st.median(stance_len)} steps; knee while the foot is down median "
      f"{st.median(stance_knee):.3f} rad (reference at the same steps {st.median(ref_stance_knee):.3f}); "
      f"hip pitch sweep over a stance median {st.median(hip_sweep):.3f} (reference {st.median(ref_hip_sweep):.3f})")
