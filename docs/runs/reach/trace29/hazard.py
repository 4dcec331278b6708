import csv, sys, collections
rows=list(csv.DictReader(open(sys.argv[1])))
eps=collections.OrderedDict()
for r in rows: eps.setdefault((r['task'],r['seed']),[]).append(r)
B=30
at_risk=collections.Counter(); falls=collections.Counter()
for e in eps.values():
    n=len(e); end=int(e[0]['end']); fell=e[0]['fell']=='1'
    walking_fall = fell and end <= n+1   # fell while the gait still walked
    for b in range(0, n, B): at_risk[b//B]+=1
    if walking_fall: falls[(n-1)//B]+=1
print("steps | walking at start of bin | falls while walking in bin | hazard per s")
for b in sorted(at_risk):
    h=falls[b]/at_risk[b]
    print(f"{b*B}-{b*B+B} | {at_risk[b]} | {falls[b]} | {h/(B/30):.3f}")
# also speed of survivors vs time
