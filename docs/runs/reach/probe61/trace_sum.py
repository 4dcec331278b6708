import csv,sys,collections
rows=list(csv.DictReader(open(sys.argv[1])))
eps=collections.defaultdict(list)
for r in rows: eps[(r['task'],r['seed'])].append(r)
f=lambda r,k: float(r[k])
fell=[e for e in eps.values() if e[0]['fell']=='1']
ok=[e for e in eps.values() if e[0]['fell']!='1']
print(f"{sys.argv[1]}: {len(eps)} episodes, {len(fell)} fell")
ks=['v_fwd','ref_v_fwd','v_lat','d_fwd','d_lat','pitch_err','roll_err','stance_mismatch','root_z','to_other','others_moved','knee_0','ref_knee_0']
import statistics as st
def agg(es, sel):
    out=[]
    for k in ks:
        vals=[f(r,k) for e in es for r in sel(e)]
        out.append(st.mean(vals) if vals else float('nan'))
    return out
print('window'.ljust(22),' '.join(k[:9].rjust(9) for k in ks))
for name,es,sel in [('ok: all walk',ok,lambda e:e),('fell: first 30',fell,lambda e:e[:30]),('fell: -60..-30',fell,lambda e:e[-60:-30]),('fell: last 30',fell,lambda e:e[-30:]),('fell: last 10',fell,lambda e:e[-10:])]:
    print(name.ljust(22),' '.join('%9.3f'%v for v in agg(es,sel)))
# others_moved in fell episodes
print('fell episodes with others_moved>0.01 at end:', sum(1 for e in fell if f(e[-1],'others_moved')>0.01), 'min to_other in fell eps median', st.median(min(f(r,'to_other') for r in e) for e in fell) if fell else '-', 'ok eps', st.median(min(f(r,'to_other') for r in e) for e in ok) if ok else '-')
print('fall steps', sorted(int(e[0]['end']) for e in fell))
