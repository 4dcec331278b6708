"""MuJoCo reference for `cargo run --release -p lhm-sim --example noise_stand -- SIGMA`: how many 30 Hz
control steps the character stands from the model's default pose when every step's PD targets are the
neutral pose plus Gaussian noise of SIGMA action units (the policy's action mapping: neutral = 0
clamped into the range, scale = distance to the farther range end), as a fresh policy with a fixed
log-std acts. A fall is the environment's rule: pelvis below 0.4 m or a body other than feet/hands
below 0.15 m. Ten seeds; prints the fall step of each (None: stood 300 steps).

Run with bench/.venv/bin/python (bench/mujoco-fidelity creates it): shows whether exploration noise
alone topples the character in MuJoCo too, i.e. whether early training falls are the physics or not.
"""
import sys

import mujoco
import numpy as np

import mujoco_fidelity as mf


def main():
    sigma = float(sys.argv[1]) if len(sys.argv) > 1 else 0.055
    model = mf.load()
    lo = np.array([model.jnt_range[model.actuator_trnid[a, 0]][0] for a in range(model.nu)])
    hi = np.array([model.jnt_range[model.actuator_trnid[a, 0]][1] for a in range(model.nu)])
    neutral = np.clip(0.0, lo, hi)
    scale = np.maximum(hi - neutral, neutral - lo)
    per_control = round(1.0 / (mf.CONTROL_HZ * model.opt.timestep))
    falls = []
    for seed in range(10):
        rng = np.random.default_rng(seed)
        data = mujoco.MjData(model)
        mujoco.mj_forward(model, data)
        probe = mf.Probe(model, data)
        fell = None
        for k in range(1, 301):
            data.ctrl[:] = np.clip(neutral + scale * sigma * rng.standard_normal(model.nu), lo, hi)
            for _ in range(per_control):
                mujoco.mj_step(model, data)
            mujoco.mj_forward(model, data)
            z = data.xpos[:, 2]
            if z[probe.pelvis] < 0.4 or min(z[b] for b in probe.checked) < 0.15:
                fell = k
                break
        falls.append(fell)
    print(f"sigma {sigma}: fall steps {falls}")


if __name__ == "__main__":
    main()
