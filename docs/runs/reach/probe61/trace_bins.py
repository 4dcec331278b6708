"""Falls by the first object's distance and the sideways motion 1-2 s in, from a fall_trace CSV."""
import csv,collections,statistics as st,sys
rows=list(csv.DictReader(open(sys.argv[1])))
eps=collections.defaultdict(list)
for r in rows: eps[(r['task'],r['seed'])].append(r)
b=collections.defaultdict(lambda:[0,0])
for e in eps.values():
    k=min(int(float(e[0]['distance'])),4); b[k][0]+=1; b[k][1]+=e[0]['fell']=='1'
print(sys.argv[1]+': episodes and falls by the object distance (m, floor):', {f'{k}-{k+1}':v for k,v in sorted(b.items())})
for name,sel in [('fell',lambda e:e[0]['fell']=='1'),('up',lambda e:e[0]['fell']!='1')]:
    es=[e for e in eps.values() if sel(e)]
    if not es: continue
    print(f"  {name} ({len(es)}): distance median {st.median(float(e[0]['distance']) for e in es):.2f} m; steps 30-60: v_fwd {st.mean(float(r['v_fwd']) for e in es for r in e[30:60]):.3f}, |v_lat| {st.mean(abs(float(r['v_lat'])) for e in es for r in e[30:60]):.3f}, |roll_err| {st.mean(abs(float(r['roll_err'])) for e in es for r in e[30:60]):.3f}")
