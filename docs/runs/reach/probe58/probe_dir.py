"""Copy a run's checkpoint into a probe dir whose config.toml has stage K's angle_offsets as its own and no [[stages]].
python3 probe_dir.py RUN_DIR OUT_DIR K   (K: the K-th [[stages]] entry that sets angle_offsets, from 1)
Why: the gait probes (cli/examples/shared/gait_run.rs) read the run's top-level [env.gait], not the stage in force;
since the fifty-ninth session they read the stage in force at the checkpoint's iteration (and lhm render-rollout,
eval, record and the vla probe since the sixtieth), and this is kept to reproduce the fifty-eighth and
fifty-ninth sessions' probes and GIF as they were run."""
import shutil, sys, pathlib
run, out, k = pathlib.Path(sys.argv[1]), pathlib.Path(sys.argv[2]), int(sys.argv[3])
out.mkdir(parents=True, exist_ok=True)
for f in run.iterdir():
    if f.name.startswith(("checkpoint", "policy")):
        shutil.copy(f, out / f.name)
lines = (run / "config.toml").read_text().splitlines()
def block(start):
    end = start + 1
    while end < len(lines) and not lines[end].startswith("["):
        end += 1
    return start, end
top = block(lines.index("[env.gait.angle_offsets]"))
stage_heads = [i for i, l in enumerate(lines) if l == "[stages.env.gait.angle_offsets]"]
s = block(stage_heads[k - 1])
first_stage = lines.index("[[stages]]")
new = lines[:top[0]] + lines[s[0]:s[1]] + lines[top[1]:first_stage]
new[top[0]] = "[env.gait.angle_offsets]"
(out / "config.toml").write_text("\n".join(new) + "\n")
print(f"{out}/config.toml: stage {k}'s offsets ({sum(1 for l in lines[s[0] + 1:s[1]] if l.strip())} DoF), no stages")
