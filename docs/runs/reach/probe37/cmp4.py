import csv,sys
# python3 cmp4.py W name=path:from ...  (W-iteration windows, episode-weighted len/falls)
W=int(sys.argv[1]); runs=[]
for a in sys.argv[2:]:
    n,rest=a.split('='); p,fr=rest.rsplit(':',1)
    runs.append((n,[r for r in csv.DictReader(open(p)) if int(r['iteration'])>int(fr)]))
def f(r,k):
    try: return float(r[k])
    except: return float('nan')
print("M     "+" | ".join(f"{n:>18}" for n,_ in runs))
k=0
while True:
    cells=[];any_=False
    for n,R in runs:
        ch=R[k*W:(k+1)*W]
        if len(ch)<W//2: cells.append(" "*18); continue
        any_=True; E=sum(f(r,'episodes') for r in ch) or 1
        ew=lambda c: sum(f(r,c)*f(r,'episodes') for r in ch)/E
        cells.append(f"{ew('mean_episode_length'):6.1f} {ew('fall_fraction'):.3f} {len(ch):4d}")
    if not any_: break
    print(f"{(k+1)*W*4096/1e6:5.2f} "+" | ".join(cells)); k+=1
