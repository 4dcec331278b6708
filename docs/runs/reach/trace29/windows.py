import csv, sys, collections, statistics as st
rows=list(csv.DictReader(open(sys.argv[1])))
eps=collections.OrderedDict()
for r in rows: eps.setdefault((r['task'],r['seed']),[]).append(r)
fell=[e for e in eps.values() if e[0]['fell']=='1']
ok=[e for e in eps.values() if e[0]['fell']=='0']
print("episodes",len(eps),"fell",len(fell),"up",len(ok))
keys=['v_fwd','dvf','dvl','dd_fwd','dd_lat','pitch_err','roll_err','rate_pitch','rate_roll','stance_mismatch','root_z']
def val(r,k):
    if k=='dvf': return float(r['v_fwd'])-float(r['ref_v_fwd'])
    if k=='dvl': return float(r['v_lat'])-float(r['ref_v_lat'])
    if k=='dd_fwd': return float(r['d_fwd'])-float(r['ref_d_fwd'])
    if k=='dd_lat': return float(r['d_lat'])-float(r['ref_d_lat'])
    return float(r[k])
def absmean(es, lo, hi, k, fromend):
    v=[]
    for e in es:
        n=len(e)
        for i,r in enumerate(e):
            j = n-i if fromend else i
            if lo<=j<hi: v.append(val(r,k))
    if not v: return float('nan'), float('nan')
    return st.mean(v), st.mean(abs(x) for x in v)
print("falls, windows by steps before the last walking step: mean / mean|.|")
wins=[(60,90),(30,60),(15,30),(0,15)]
print("%-16s"%"key"+"".join("%18s"%f"{a}-{b} before" for a,b in wins))
for k in keys:
    print("%-16s"%k+"".join("%9.3f/%-8.3f"%absmean(fell,a,b,k,True) for a,b in wins))
print("by time from start (steps): falls | up")
tw=[(0,30),(30,60),(60,90),(90,120)]
for k in keys:
    print("%-16s"%k+"".join("%9.3f/%-8.3f"%absmean(fell,a,b,k,False) for a,b in tw)+" | "+"".join("%9.3f/%-8.3f"%absmean(ok,a,b,k,False) for a,b in tw))
