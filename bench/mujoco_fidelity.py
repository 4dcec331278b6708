"""MuJoCo reference for `lhm bench fidelity`: how the character file (sim/assets/amp_humanoid.xml)
behaves in MuJoCo, so the rapier simulator's figures (the same keys, printed by the Rust command) can be
judged against a well-tested engine. The file's own settings (implicitfast, 1/120 s steps) with the
Newton solver at 100 iterations; 30 Hz control = 4 physics steps per control step.

Scenarios, each from the model's default pose (pelvis at 0.89 m, joints 0) at rest, 5 s unless noted:
  passive_drop  no actuator force at all: how the body collapses and lands.
  neutral_hold  every PD target 0 rad (the neutral pose): does it stand, track, keep its feet still?
  zero_action   targets from the policy action mapping with action 0; must equal neutral_hold.
  landing       neutral_hold spawned 0.10 m higher, 2 s: impact and settling forces.
  servo_step    root welded in place, right knee target stepped to 70 deg: PD servo response.
  collapse      servos off for 3 s, on through the fall: how far joints go past their ranges.
Per scenario: fall step, pelvis height and tilt, joint tracking error, foot slide, floor penetration,
floor normal forces against body weight, wall time (includes the measuring, an mj_forward per step).

Body poses and contacts are read after mj_forward of the current state: after mj_step, data.xpos and
data.contact belong to the state at the START of that step.

Run through bench/mujoco-fidelity (installs mujoco into bench/.venv). Prints JSON (--json is accepted).
"""
import json
import math
import statistics
import time
from pathlib import Path

import mujoco
import numpy as np

ROOT = Path(__file__).resolve().parent.parent
XML = ROOT / "sim" / "assets" / "amp_humanoid.xml"
CONTROL_HZ = 30
FALL_PELVIS_HEIGHT = 0.5
FALL_BODY_HEIGHT = 0.15
REPORT_TIMES = {"0.5": 15, "1": 30, "2": 60, "5": 150}  # seconds -> control step
WINDOW_START = 15  # control step at t = 0.5 s: measurements that skip the initial settling start here
SERVO_KNEE_TARGET_DEG = 70.0
SERVO_REPORT_STEPS = {"0.03": 4, "0.1": 12, "0.2": 24, "0.5": 60}  # seconds -> physics step


def load(xml_text=None):
    model = (mujoco.MjModel.from_xml_string(xml_text) if xml_text
             else mujoco.MjModel.from_xml_path(str(XML)))
    model.opt.solver = mujoco.mjtSolver.mjSOL_NEWTON
    model.opt.iterations = 100
    return model


def name_of(model, kind, i):
    return mujoco.mj_id2name(model, kind, i) or ""


def action_targets(model, action):
    """PD targets (radians) for a policy action: neutral = 0 clamped into the joint's range; a hinge
    alone in its body (elbow, knee) scales by half its range, the others by the distance from neutral
    to the farther range end; the target is clamped into the range."""
    hinges_per_body = {}
    for j in range(model.njnt):
        if model.jnt_type[j] == mujoco.mjtJoint.mjJNT_HINGE:
            hinges_per_body[model.jnt_bodyid[j]] = hinges_per_body.get(model.jnt_bodyid[j], 0) + 1
    targets = np.zeros(model.nu)
    for a in range(model.nu):
        j = model.actuator_trnid[a, 0]
        lo, hi = model.jnt_range[j]
        neutral = min(max(0.0, lo), hi)
        if hinges_per_body[model.jnt_bodyid[j]] == 1:
            scale = 0.5 * (hi - lo)
        else:
            scale = max(hi - neutral, neutral - lo)
        targets[a] = min(max(neutral + scale * action[a], lo), hi)
    return targets


class Probe:
    """Reads the measured quantities from a model/data pair (after mj_forward)."""

    def __init__(self, model, data):
        self.model, self.data = model, data
        body = lambda n: mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, n)
        geom = lambda n: mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, n)
        self.pelvis = body("pelvis")
        self.feet = [body("right_foot"), body("left_foot")]
        self.foot_geoms = {geom("right_foot"), geom("left_foot")}
        self.floor = geom("floor")
        self.checked = [b for b in range(1, model.nbody)
                        if not name_of(model, mujoco.mjtObj.mjOBJ_BODY, b).endswith(("foot", "hand"))]
        self.joint_qpos = [model.jnt_qposadr[model.actuator_trnid[a, 0]] for a in range(model.nu)]
        self.joint_names = [name_of(model, mujoco.mjtObj.mjOBJ_JOINT, model.actuator_trnid[a, 0])
                            for a in range(model.nu)]
        self._force = np.zeros(6)

    def fallen(self):
        z = self.data.xpos[:, 2]
        return z[self.pelvis] < FALL_PELVIS_HEIGHT or min(z[b] for b in self.checked) < FALL_BODY_HEIGHT

    def height(self):
        return float(self.data.xpos[self.pelvis, 2])

    def tilt_deg(self):
        zz = self.data.xmat[self.pelvis].reshape(3, 3)[2, 2]  # world z of the pelvis's local z axis
        return math.degrees(math.acos(min(max(zz, -1.0), 1.0)))

    def tracking_errors_deg(self):
        angles = self.data.qpos[self.joint_qpos]
        return np.degrees(np.abs(angles - self.data.ctrl))

    def floor_contacts(self):
        c = self.data.contact
        for i in range(self.data.ncon):
            if self.floor in (c.geom1[i], c.geom2[i]):
                yield i, int(c.geom2[i] if c.geom1[i] == self.floor else c.geom1[i])

    def penetration(self):
        return max([0.0] + [-float(self.data.contact.dist[i]) for i, _ in self.floor_contacts()])

    def floor_force(self):
        total = 0.0
        for i, _ in self.floor_contacts():
            mujoco.mj_contactForce(self.model, self.data, i, self._force)
            total += self._force[0]
        return total

    def both_feet_down(self):
        return self.foot_geoms <= {g for _, g in self.floor_contacts()}

    def feet_xy(self):
        return [self.data.xpos[b, :2].copy() for b in self.feet]


def rnd(x, digits):
    return None if x is None else round(float(x), digits)


def run_scenario(model, targets, control_steps, lift=0.0, actuated=True):
    data = mujoco.MjData(model)
    data.qpos[2] += lift
    data.ctrl[:] = targets
    mujoco.mj_forward(model, data)
    probe = Probe(model, data)
    per_control = round(1.0 / (CONTROL_HZ * model.opt.timestep))
    weight = float(sum(model.body_mass)) * -model.opt.gravity[2]
    # Per control step k (1-based), sampled at its end; penetration per physics step.
    fall_step, both_down_step = None, None
    heights, tilts, forces, errors, feet, penetration = {}, {}, {}, {}, {}, {}
    start = time.perf_counter()
    for k in range(1, control_steps + 1):
        deepest = 0.0
        for _ in range(per_control):
            mujoco.mj_step(model, data)
            mujoco.mj_forward(model, data)
            deepest = max(deepest, probe.penetration())
        penetration[k] = deepest
        heights[k], tilts[k] = probe.height(), probe.tilt_deg()
        forces[k] = probe.floor_force()
        errors[k] = probe.tracking_errors_deg()
        feet[k] = probe.feet_xy()
        if both_down_step is None and probe.both_feet_down():
            both_down_step = k
        if fall_step is None and probe.fallen():
            fall_step = k
    wall = time.perf_counter() - start

    last = control_steps if fall_step is None else fall_step - 1  # last step before the fall
    window = range(WINDOW_START, last + 1)  # t = 0.5 s .. the fall (exclusive) or the end
    out = {"wall_s": round(wall, 3), "fall_step": fall_step}
    out["root_height_m"] = {t: rnd(heights[k], 4) for t, k in REPORT_TIMES.items() if k <= control_steps}
    out["pelvis_tilt_deg"] = {t: rnd(tilts[k], 2) for t, k in REPORT_TIMES.items() if k <= control_steps}
    if actuated and len(window) > 0:
        per_joint = np.max([errors[k] for k in window], axis=0)
        out["max_tracking_error_deg"] = rnd(per_joint.max(), 3)
        out["tracking_error_deg_by_joint"] = {n: rnd(e, 3) for n, e in zip(probe.joint_names, per_joint)}
    else:
        out["max_tracking_error_deg"] = None
        out["tracking_error_deg_by_joint"] = {}
    if len(window) > 0:
        slide = max(float(np.linalg.norm(feet[last][f] - feet[WINDOW_START][f])) for f in range(2))
        elapsed = (last - WINDOW_START) / CONTROL_HZ
        out["foot_slide_m"] = rnd(slide, 5)
        out["foot_slide_m_per_s"] = rnd(slide / elapsed, 5) if elapsed > 0 else None
    else:
        out["foot_slide_m"] = out["foot_slide_m_per_s"] = None
    # Landing measures penetration over the whole run, the others from t = 0.5 s.
    pen_steps = range(1, last + 1) if lift > 0 else window
    out["max_penetration_m"] = rnd(max([penetration[k] for k in pen_steps], default=None), 5)
    window_forces = [forces[k] for k in window]
    out["contact_force_mean_n"] = rnd(statistics.fmean(window_forces), 1) if window_forces else None
    out["contact_force_std_n"] = rnd(statistics.pstdev(window_forces), 1) if window_forces else None
    out["first_contact_forces_n"] = [rnd(forces[k], 1) for k in range(1, min(10, control_steps) + 1)]
    after = []
    if both_down_step is not None:
        end = min(2 * CONTROL_HZ, control_steps, last)
        after = [forces[k] for k in range(both_down_step + 1, end + 1)]
    out["min_force_after_both_feet_down_n"] = rnd(min(after), 1) if after else None
    out["body_weight_n"] = rnd(weight, 1)
    return out


def passive_model():
    model = load()
    model.actuator_gainprm[:, 0] = 0.0
    model.actuator_biasprm[:, 1:3] = 0.0
    return model


def servo_step():
    """Root welded (freejoint removed from the XML), all targets 0 but the right knee's: 70 deg.
    Reports target - angle (degrees) after the physics steps nearest SERVO_REPORT_STEPS' times."""
    text = XML.read_text()
    assert '<freejoint name="root"/>' in text
    model = load(text.replace('<freejoint name="root"/>', ""))
    data = mujoco.MjData(model)
    knee = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_ACTUATOR, "right_knee")
    knee_qpos = model.jnt_qposadr[model.actuator_trnid[knee, 0]]
    target = math.radians(SERVO_KNEE_TARGET_DEG)
    data.ctrl[knee] = target
    errors = {}
    start = time.perf_counter()
    for n in range(1, max(SERVO_REPORT_STEPS.values()) + 1):
        mujoco.mj_step(model, data)
        for t, step in SERVO_REPORT_STEPS.items():
            if step == n:
                errors[t] = rnd(math.degrees(target - data.qpos[knee_qpos]), 3)
    return {"wall_s": round(time.perf_counter() - start, 4), "knee_error_deg": errors}


COLLAPSE_S = 3.0


def collapse():
    """Servos off for COLLAPSE_S seconds, on through the fall; per actuated joint, the largest
    amount (degrees) its angle lay outside its range at the end of a control step."""
    model = passive_model()
    data = mujoco.MjData(model)
    per_control = round(1.0 / (CONTROL_HZ * model.opt.timestep))
    joints = [model.actuator_trnid[a, 0] for a in range(model.nu)]
    names = [name_of(model, mujoco.mjtObj.mjOBJ_JOINT, j) for j in joints]
    worst = np.zeros(len(joints))
    per_step_worst = []
    start = time.perf_counter()
    for _ in range(round(COLLAPSE_S * CONTROL_HZ)):
        for _ in range(per_control):
            mujoco.mj_step(model, data)
        q = data.qpos[[model.jnt_qposadr[j] for j in joints]]
        lo, hi = model.jnt_range[joints, 0], model.jnt_range[joints, 1]
        excess = np.maximum(np.maximum(lo - q, q - hi), 0.0)
        per_step_worst.append(excess.max())
        worst = np.maximum(worst, excess)
    return {
        "mean_limit_excess_deg": rnd(math.degrees(statistics.fmean(per_step_worst)), 3),
        "max_limit_excess_deg": rnd(math.degrees(worst.max()), 3),
        "limit_excess_deg_by_joint": {n: rnd(math.degrees(w), 3) for n, w in zip(names, worst)},
        "wall_s": round(time.perf_counter() - start, 4),
    }


def main():
    model = load()
    steps = 5 * CONTROL_HZ
    out = {"settings": {
        "engine": f"mujoco {mujoco.__version__} (python)",
        "timestep": model.opt.timestep,
        "solver": mujoco.mjtSolver(model.opt.solver).name.removeprefix("mjSOL_").lower(),
        "iterations": int(model.opt.iterations),
        "integrator": mujoco.mjtIntegrator(model.opt.integrator).name.removeprefix("mjINT_").lower(),
        "physics_steps_per_control": round(1.0 / (CONTROL_HZ * model.opt.timestep)),
    }}
    zeros = np.zeros(model.nu)
    out["passive_drop"] = run_scenario(passive_model(), zeros, steps, actuated=False)
    out["neutral_hold"] = run_scenario(load(), zeros, steps)
    out["zero_action"] = run_scenario(load(), action_targets(model, zeros), steps)
    out["landing"] = run_scenario(load(), zeros, 2 * CONTROL_HZ, lift=0.10)
    out["servo_step"] = servo_step()
    out["collapse"] = collapse()
    print(json.dumps(out, indent=2))


if __name__ == "__main__":
    main()  # any argument (e.g. --json) is ignored: the output is always JSON
