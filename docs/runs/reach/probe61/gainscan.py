"""Falls of the frozen x0.75 policy (probe59, 18,841) with the gait base's gains scaled, by `lhm eval`.

python3 gainscan.py GROUP=SCALE ...  (groups below; walks from the task's start, `cfg-v075.toml`)
`evaluate` is also what rampscan.py and the 4-seed runs used (seeds=4)."""
import re, sys, subprocess, csv

POLICY = '/work/main/docs/runs/reach/probe59/acc80-curriculum-free-d/policy'
base = open('cfg-v075.toml').read()


def scaled(text, mult):
    """`text` with each `name = value` line of `mult`'s names times its factor."""
    for g, m in mult.items():
        text = re.sub(rf'^{g} = (\S+)$', lambda mm: f"{g} = {float(mm.group(1)) * m}", text, flags=re.M)
    return text


def evaluate(tag, config_text, rest=False, seeds=2):
    """66 unseen tasks x `seeds`, first pair, 300 steps, mean actions; prints falls before/after reaching."""
    open(f'/tmp/cfg-{tag}.toml', 'w').write(config_text)
    cmd = ['/work/main/target/release/lhm', 'eval', '--policy', POLICY, '--config', f'/tmp/cfg-{tag}.toml',
           '--first-pair', '--max-steps', '300', '--seeds', str(seeds), '-o', f'/tmp/ev-{tag}'] + (['--from-rest'] if rest else [])
    subprocess.run(cmd, capture_output=True, check=True)
    r = list(csv.DictReader(open(f'/tmp/ev-{tag}/episodes.csv')))
    fb = sum(1 for x in r if x['fell'] == '1' and x['reach_step'] == '')
    fa = sum(1 for x in r if x['fell'] == '1' and x['reach_step'] != '')
    reached = sum(1 for x in r if x['reach_step'] != '')
    print(f"{tag}: falls {fb + fa}/{len(r)} (before reach {fb}, after {fa}), reached {reached}", flush=True)


def run(tag, mult, rest=False, seeds=2):
    evaluate(tag, scaled(base, mult), rest, seeds)


groups = {'lat': ['swing_d_lat', 'swing_v_lat', 'stance_roll', 'stance_roll_rate', 'ankle_v_lat', 'abdomen_roll'],
          'fwd': ['swing_d_fwd', 'swing_v_fwd', 'stance_pitch', 'stance_pitch_rate', 'ankle_v_fwd', 'ankle_pitch', 'abdomen_pitch'],
          'swinglat': ['swing_d_lat', 'swing_v_lat'], 'stanceroll': ['stance_roll', 'stance_roll_rate']}

if __name__ == '__main__':
    for arg in sys.argv[1:]:
        grp, sc = arg.split('=')
        run(f'{grp}x{sc}', {g: float(sc) for g in groups[grp]})
