"""MuJoCo reference for `lhm bench env`: steps the same character file (sim/assets/amp_humanoid.xml)
with the same settings -- 1/120 s physics steps, 4 per 30 Hz control step, the same action mapping
and action stream, episodes restored on a fall (a body other than feet and hands below 0.15 m,
the env's rule) or after 150 control steps -- on one core, from Python. MuJoCo has no substeps:
120 Hz physics is 4 steps of 1/120 s per control step. It reports how often MuJoCo itself reset an
unstable state (its "bad qacc" warning), which would make its figure less comparable.
After mj_step, data.xpos still holds the pose at the START of that step, so the fall check runs
mj_kinematics first (cheap: forward kinematics only, once per control step, the env's own cost too).

Run through bench/run-mujoco (installs mujoco into bench/.venv). Prints JSON.
"""
import json
import math
import statistics
import sys
import time
from pathlib import Path

import mujoco

ROOT = Path(__file__).resolve().parent.parent
XML = ROOT / "sim" / "assets" / "amp_humanoid.xml"
EPISODE = 150
FALL_HEIGHT = 0.15


def action_stream(seed, n):
    # Same LCG as sim/src/bench.rs: uniform in [-0.5, 0.5].
    s = (seed ^ 0x9E3779B97F4A7C15) & (2**64 - 1)
    out = []
    for _ in range(n):
        s = (s * 6364136223846793005 + 1442695040888963407) & (2**64 - 1)
        out.append((s >> 40) / float(1 << 24) - 0.5)
    return out


def action_mapping(model):
    """Per actuator: (offset, scale, lo, hi), as sim/src/character.rs computes them."""
    out = []
    for a in range(model.nu):
        j = model.actuator_trnid[a, 0]
        lo, hi = model.jnt_range[j]
        offset = min(max(0.0, lo), hi)  # zero action = the neutral pose
        out.append((offset, max(hi - offset, offset - lo), lo, hi))
    return out


def checked_bodies(model):
    """Body ids the fall rule looks at: all but the world, feet and hands."""
    out = []
    for b in range(1, model.nbody):
        name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, b) or ""
        if not (name.endswith("foot") or name.endswith("hand")):
            out.append(b)
    return out


def run(steps, reps):
    model = mujoco.MjModel.from_xml_path(str(XML))
    data = mujoco.MjData(model)
    mapping = action_mapping(model)
    per_control = round((1.0 / 30.0) / model.opt.timestep)
    actions = action_stream(7, EPISODE * model.nu)
    start_qpos = data.qpos.copy()
    checked = checked_bodies(model)
    rates = []
    episodes = 0
    unstable = 0
    for _ in range(reps + 1):
        mujoco.mj_resetData(model, data)
        data.qpos[:] = start_qpos
        k = 0
        t = time.perf_counter()
        for step in range(steps):
            if k > 0:
                mujoco.mj_kinematics(model, data)  # after mj_step, xpos is from the step's start
            fell = k > 0 and min(data.xpos[b][2] for b in checked) < FALL_HEIGHT
            if k >= EPISODE or fell:
                unstable += data.warning[mujoco.mjtWarning.mjWARN_BADQACC].number
                mujoco.mj_resetData(model, data)
                data.qpos[:] = start_qpos
                k = 0
                episodes += 1
            a = actions[k * model.nu:(k + 1) * model.nu]
            for i, (off, scale, lo, hi) in enumerate(mapping):
                data.ctrl[i] = min(max(off + scale * a[i], lo), hi)
            mujoco.mj_step(model, data, nstep=per_control)
            k += 1
        unstable += data.warning[mujoco.mjtWarning.mjWARN_BADQACC].number
        episodes += 1
        rates.append(steps / (time.perf_counter() - t))
    rates = rates[1:]  # the first run is the warm-up
    return {
        "engine": f"mujoco {mujoco.__version__} (python)",
        "timestep": model.opt.timestep,
        "physics_steps_per_control": per_control,
        "bodies": model.nbody - 1,
        "actuated_dofs": model.nu,
        "mass_kg": round(float(sum(model.body_mass)), 2),
        "steps_per_repetition": steps,
        "repetitions": reps,
        "mean_episode_steps": round(steps * (reps + 1) / episodes, 1),
        "unstable_resets": unstable,
        "control_steps_per_s_per_core": round(statistics.median(rates)),
        "physics_steps_per_s_per_core": round(statistics.median(rates) * per_control),
    }


if __name__ == "__main__":
    steps = int(sys.argv[1]) if len(sys.argv) > 1 else 600
    reps = int(sys.argv[2]) if len(sys.argv) > 2 else 5
    print(json.dumps(run(steps, reps), indent=2))
