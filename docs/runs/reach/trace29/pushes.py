import csv, sys, collections
rows=list(csv.DictReader(open(sys.argv[1])))
eps=collections.OrderedDict()
for r in rows: eps.setdefault((r['task'],r['seed']),[]).append(r)
bins=[(0,2),(2,3),(3,4),(4,9)]
print("bin | episodes | fell | fell & pushed>5cm | up & pushed>5cm | fell no push")
tot=collections.Counter()
for lo,hi in bins:
    c=collections.Counter()
    for k,e in eps.items():
        d=float(e[0]['distance'])
        if not lo<=d<hi: continue
        fell=e[0]['fell']=='1'; pushed=max(float(r['others_moved']) for r in e)>0.05
        c['n']+=1; c['fell']+=fell; c['fp']+=fell and pushed; c['up_p']+=(not fell) and pushed; c['fnp']+=fell and not pushed
    print(f"{lo}-{hi} m | {c['n']} | {c['fell']} | {c['fp']} | {c['up_p']} | {c['fnp']}")
    tot+=c
print("all |",tot['n'],'|',tot['fell'],'|',tot['fp'],'|',tot['up_p'],'|',tot['fnp'])
