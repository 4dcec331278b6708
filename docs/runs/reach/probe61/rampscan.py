import re,subprocess,csv,sys
base=open('cfg-v075.toml').read()
head,rest=base.split('[env.gait.start]\n',1)
start,tail=rest.split('\n[env.gait.stop]',1)
def run(tag,mult):
    s=start
    for g,m in mult.items():
        s=re.sub(rf'^{g} = (\S+)$', lambda mm: f"{g} = {float(mm.group(1))*m}", s, flags=re.M)
    open(f'/tmp/cfg-{tag}.toml','w').write(head+'[env.gait.start]\n'+s+'\n[env.gait.stop]'+tail)
    cmd=['/work/main/target/release/lhm','eval','--policy','/work/main/docs/runs/reach/probe59/acc80-curriculum-free-d/policy','--config',f'/tmp/cfg-{tag}.toml','--first-pair','--max-steps','300','--seeds','2','-o',f'/tmp/ev-{tag}','--from-rest']
    subprocess.run(cmd,capture_output=True,check=True)
    r=list(csv.DictReader(open(f'/tmp/ev-{tag}/episodes.csv')))
    fb=sum(1 for x in r if x['fell']=='1' and x['reach_step']=='')
    fa=sum(1 for x in r if x['fell']=='1' and x['reach_step']!='')
    re_=sum(1 for x in r if x['reach_step']!='')
    print(f"{tag}: falls {fb+fa}/{len(r)} (before reach {fb}, after {fa}), reached {re_}", flush=True)
for arg in sys.argv[1:]:
    g,sc=arg.split('=')
    run(f'rest-{g}x{sc}',{g:float(sc)} if g!='none' else {})
