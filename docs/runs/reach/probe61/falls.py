import csv,sys,statistics as st
r=list(csv.DictReader(open(sys.argv[1]+'/episodes.csv')))
n=len(r)
fb=[x for x in r if x['fell']=='1' and x['reach_step']=='']
fa=[x for x in r if x['fell']=='1' and x['reach_step']!='']
re=sum(x['reach_step']!='' for x in r)
print(f"{sys.argv[1]}: episodes {n}, reached {re}, fell before reach {len(fb)} (median step {st.median([int(x['steps']) for x in fb]) if fb else '-'}), fell after reach {len(fa)} (median steps after reach {st.median([int(x['steps'])-int(x['reach_step']) for x in fa]) if fa else '-'})")
