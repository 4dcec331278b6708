import re,sys,subprocess,csv
# usage: gainscan.py NAME "gain1,gain2" scale...  -> eval of the frozen x0.75 policy, walks from the task start
base=open('cfg-v075.toml').read()
def cfg(mult):
    s=base
    for g,m in mult.items():
        s=re.sub(rf'^{g} = (\S+)$', lambda mm: f"{g} = {float(mm.group(1))*m}", s, flags=re.M)
    return s
def run(tag,mult,rest=False):
    open(f'/tmp/cfg-{tag}.toml','w').write(cfg(mult))
    cmd=['/work/main/target/release/lhm','eval','--policy','/work/main/docs/runs/reach/probe59/acc80-curriculum-free-d/policy','--config',f'/tmp/cfg-{tag}.toml','--first-pair','--max-steps','300','--seeds','2','-o',f'/tmp/ev-{tag}']+(['--from-rest'] if rest else [])
    subprocess.run(cmd,capture_output=True,check=True)
    r=list(csv.DictReader(open(f'/tmp/ev-{tag}/episodes.csv')))
    fb=sum(1 for x in r if x['fell']=='1' and x['reach_step']=='')
    fa=sum(1 for x in r if x['fell']=='1' and x['reach_step']!='')
    re_=sum(1 for x in r if x['reach_step']!='')
    print(f"{tag}: falls {fb+fa}/{len(r)} (before reach {fb}, after {fa}), reached {re_}", flush=True)
groups={'lat':['swing_d_lat','swing_v_lat','stance_roll','stance_roll_rate','ankle_v_lat','abdomen_roll'],
        'fwd':['swing_d_fwd','swing_v_fwd','stance_pitch','stance_pitch_rate','ankle_v_fwd','ankle_pitch','abdomen_pitch'],
        'swinglat':['swing_d_lat','swing_v_lat'],'stanceroll':['stance_roll','stance_roll_rate']}
for arg in sys.argv[1:]:
    grp,sc=arg.split('=')
    run(f'{grp}x{sc}',{g:float(sc) for g in groups[grp]})
