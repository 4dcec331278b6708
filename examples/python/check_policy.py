#!/usr/bin/env python3
"""Runs a published policy with numpy on the observations of trajectory chunks, and checks the
chunks against it: the log-probability of each recorded action and each recorded value,
recomputed here, against what the actor wrote.

    check_policy.py --weights policy.bin --chunk chunk-0.bin [--chunk ...]

Files hold one encoded message each (PolicyWeights, TrajectoryChunk), e.g. as saved by
subscribe.py --save DIR. Prints one JSON object: per chunk, its size and the largest
differences; the mean actions of the first observation.
"""

import argparse
import json
import sys

import numpy as np

from lhm_wire import Policy, decode


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--weights", required=True, help="a PolicyWeights message")
    ap.add_argument("--chunk", action="append", default=[], help="a TrajectoryChunk message")
    a = ap.parse_args()
    with open(a.weights, "rb") as f:
        policy = Policy(f.read())
    report = {"run_id": policy.run_id, "version": policy.version, "chunks": []}
    for path in a.chunk:
        with open(path, "rb") as f:
            c = decode(f.read(), "TrajectoryChunk")
        n = c["num_steps"]
        if c["obs_dim"] != policy.obs_dim or c["act_dim"] != policy.act_dim:
            sys.exit(
                f"{path}: chunk is {c['obs_dim']}x{c['act_dim']}, policy {policy.obs_dim}x{policy.act_dim}"
            )
        obs = np.asarray(c["observations"]).reshape(n, c["obs_dim"])
        actions = np.asarray(c["actions"]).reshape(n, c["act_dim"])
        lp = policy.log_prob(obs, actions)
        v = policy.values(obs)
        report["chunks"].append(
            {
                "file": path,
                "policy_version": c["policy_version"],
                "num_steps": n,
                "episodes": len(c["episodes"]),
                "reward_sum": float(np.sum(c["rewards"])),
                "max_abs_log_prob_error": float(np.max(np.abs(lp - np.asarray(c["log_probs"])))),
                "max_abs_value_error": float(np.max(np.abs(v - np.asarray(c["values"])))),
                "mean_action_of_first_obs": policy.mean_actions(obs[:1])[0].tolist(),
            }
        )
    print(json.dumps(report))


if __name__ == "__main__":
    main()
