"""Windows of two runs side by side, counted from a stage start: python3 cmp.py A/metrics.csv A_FROM_ITERATION B/metrics.csv B_FROM_ITERATION (200-iteration windows, episode-weighted)."""
import csv,sys
def load(p, start):
    rows=[r for r in csv.DictReader(open(p)) if int(r['iteration'])>start]
    return rows
def f(r,k):
    try: return float(r[k])
    except: return float('nan')
def win(rows,w):
    out=[]
    for i in range(0,len(rows),w):
        ch=rows[i:i+w]; E=sum(f(r,'episodes') for r in ch) or 1
        ew=lambda k: sum(f(r,k)*f(r,'episodes') for r in ch if f(r,k)==f(r,k))/E
        out.append((len(ch),ew('mean_episode_length'),ew('fall_fraction'),ew('task_start_fall_fraction'),ew('reach_rate'),ew('reach_rate_all')))
    return out
a=win(load(sys.argv[1],int(sys.argv[2])),200); b=win(load(sys.argv[3],int(sys.argv[4])),200)
print("M-into-stage | A len fall tsfall reachR reachA | B len fall tsfall reachR reachA")
for k in range(max(len(a),len(b))):
    s=lambda x: " ".join(f"{v:.3f}" if j else f"{v:5.1f}" for j,v in enumerate(x[1:])) if x else "-"
    print(f"{(k+1)*200*4096/1e6:5.2f} | {s(a[k] if k<len(a) else None)} | {s(b[k] if k<len(b) else None)}")
