#!/usr/bin/env python3
"""Listens to a running lhm learner's run over zenoh: fetches the latest policy weights, then
prints one line per trajectory chunk the actors send (actor, steps, reward, finished episodes)
and checks each chunk's log-probabilities against the latest weights with numpy.

    subscribe.py --connect tcp/127.0.0.1:7447 --run-id teacher1 [--role teacher1]
                 [--count 20] [--save DIR]

--save DIR writes policy.bin and chunk-<n>.bin (the raw messages) for check_policy.py.
Needs `pip install numpy eclipse-zenoh`.
"""

import argparse
import json
import os
import queue

import numpy as np
import zenoh

from lhm_wire import Policy, decode


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--connect", required=True, help="the learner's endpoint, e.g. tcp/127.0.0.1:7447")
    ap.add_argument("--run-id", default="teacher1")
    ap.add_argument("--role", default="teacher1", help="teacher1, teacher2, student or vla")
    ap.add_argument("--count", type=int, default=20, help="stop after this many chunks")
    ap.add_argument("--save", help="write the raw messages to this directory")
    a = ap.parse_args()

    conf = zenoh.Config()
    conf.insert_json5("mode", '"client"')
    conf.insert_json5("connect/endpoints", json.dumps([a.connect]))
    policy_key = f"lhm/{a.run_id}/policy/{a.role}"
    traj_key = f"lhm/{a.run_id}/traj/{a.role}/*"
    if a.save:
        os.makedirs(a.save, exist_ok=True)
    with zenoh.open(conf) as session:
        weights = None
        for reply in session.get(policy_key):
            if reply.ok is not None:
                weights = reply.ok.payload.to_bytes()
        if weights is None:
            raise SystemExit(f"no weights on {policy_key}: is the learner of run {a.run_id} up?")
        policy = Policy(weights)
        print(f"policy version {policy.version}: {policy.obs_dim} observations -> {policy.act_dim} actions")
        if a.save:
            with open(os.path.join(a.save, "policy.bin"), "wb") as f:
                f.write(weights)
        inbox = queue.Queue()
        session.declare_subscriber(traj_key, lambda s: inbox.put(s.payload.to_bytes()))
        session.declare_subscriber(policy_key, lambda s: inbox.put(("w", s.payload.to_bytes())))
        seen = 0
        while seen < a.count:
            item = inbox.get()
            if isinstance(item, tuple):
                policy = Policy(item[1])
                continue
            c = decode(item, "TrajectoryChunk")
            n = c["num_steps"]
            obs = np.asarray(c["observations"]).reshape(n, c["obs_dim"])
            lp = policy.log_prob(obs, np.asarray(c["actions"]).reshape(n, c["act_dim"]))
            same = c["policy_version"] == policy.version
            err = float(np.max(np.abs(lp - np.asarray(c["log_probs"])))) if same else float("nan")
            print(
                f"{c['actor_id']} chunk {c['chunk_seq']} env {c['env_index']}: {n} steps of "
                f"version {c['policy_version']}, reward {np.sum(c['rewards']):.2f}, "
                f"{len(c['episodes'])} episodes ended, log-prob error {err:.2e}"
            )
            if a.save:
                with open(os.path.join(a.save, f"chunk-{seen}.bin"), "wb") as f:
                    f.write(item)
            seen += 1


if __name__ == "__main__":
    main()
