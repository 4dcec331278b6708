#!/usr/bin/env python3
"""PyTorch CPU reference for `lhm_learner::bench` (learner/src/bench.rs): times the same two steps
with the same networks, batch and optimiser settings, on 2 threads.

PPO minibatch step: Gaussian policy MLP 256-1024-512-28 (ELU, fixed log-std -2.9) and value MLP
256-1024-512-1, clipped surrogate + clipped value loss (coef 5) + action-bound loss (coef 10),
backward, global grad-norm clip 1.0, Adam lr 2e-5, minibatch 4096.
AMP step: discriminator 1050-1024-512-1 (ELU) on 4096 demo + 4096 agent rows, BCE with logits,
gradient penalty 5 on demo inputs (autograd double-backward here; forward-op input gradient on
the Rust side), logit reg 0.01, weight decay 1e-4, Adam lr 1e-4.

Usage: python3 bench/learner_torch.py [--threads 2] [--reps 7] [--warmup 2]
Prints JSON with the median milliseconds per step and samples per second.
"""
import argparse
import json
import math
import statistics
import time

import torch
from torch import nn

OBS, ACT, FEAT, BATCH = 256, 28, 1050, 4096
HIDDEN = [1024, 512]


def mlp(inp, out, hidden):
    layers, fan_in = [], inp
    for h in hidden:
        layers += [nn.Linear(fan_in, h), nn.ELU()]
        fan_in = h
    layers.append(nn.Linear(fan_in, out))
    return nn.Sequential(*layers)


def time_steps(step, warmup, reps):
    for _ in range(warmup):
        step()
    times = []
    for _ in range(reps):
        t0 = time.perf_counter()
        step()
        times.append((time.perf_counter() - t0) * 1e3)
    times.sort()
    med = statistics.median(times)
    return {"median_ms": med, "min_ms": times[0], "max_ms": times[-1], "samples_per_s": BATCH / (med / 1e3)}


def ppo_bench(warmup, reps):
    torch.manual_seed(1)
    policy, value = mlp(OBS, ACT, HIDDEN), mlp(OBS, 1, HIDDEN)
    log_std = torch.full((ACT,), -2.9)
    params = list(policy.parameters()) + list(value.parameters())
    opt = torch.optim.Adam(params, lr=2e-5, betas=(0.9, 0.999), eps=1e-8)
    obs, actions = torch.randn(BATCH, OBS), torch.randn(BATCH, ACT)

    def log_prob(mean):
        z = (actions - mean) / log_std.exp()
        return -0.5 * (z * z).sum(-1) - log_std.sum() - 0.5 * ACT * math.log(2 * math.pi)

    with torch.no_grad():
        old_lp = log_prob(policy(obs))
        old_v = value(obs).squeeze(-1)
    adv = torch.randn(BATCH)
    ret = old_v + adv
    eps, vclip = 0.2, 0.2

    def step():
        mean = policy(obs)
        ratio = torch.exp(log_prob(mean) - old_lp)
        pl = -torch.min(ratio * adv, ratio.clamp(1 - eps, 1 + eps) * adv).mean()
        v = value(obs).squeeze(-1)
        vc = old_v + (v - old_v).clamp(-vclip, vclip)
        vl = 0.5 * torch.max((v - ret) ** 2, (vc - ret) ** 2).mean()
        bl = (torch.relu(mean - 1) ** 2 + torch.relu(-mean - 1) ** 2).sum(-1).mean()
        loss = pl + 5.0 * vl + 10.0 * bl
        opt.zero_grad(set_to_none=True)
        loss.backward()
        torch.nn.utils.clip_grad_norm_(params, 1.0)
        opt.step()

    return time_steps(step, warmup, reps)


def amp_bench(warmup, reps):
    torch.manual_seed(2)
    disc = mlp(FEAT, 1, HIDDEN)
    opt = torch.optim.Adam(disc.parameters(), lr=1e-4, betas=(0.9, 0.999), eps=1e-8)
    demo, agent = torch.randn(BATCH, FEAT), torch.randn(BATCH, FEAT)
    weights = [m.weight for m in disc if isinstance(m, nn.Linear)]
    bce = nn.functional.binary_cross_entropy_with_logits

    def step():
        d_in = demo.clone().requires_grad_(True)
        d_demo = disc(d_in).squeeze(-1)
        d_agent = disc(agent).squeeze(-1)
        loss = 0.5 * (bce(d_demo, torch.ones_like(d_demo)) + bce(d_agent, torch.zeros_like(d_agent)))
        (g,) = torch.autograd.grad(d_demo.sum(), d_in, create_graph=True)
        gp = (g * g).sum(-1).mean()
        logit_reg = (weights[-1] ** 2).sum()
        wd = sum((w ** 2).sum() for w in weights)
        total = loss + 5.0 * gp + 0.01 * logit_reg + 1e-4 * wd
        opt.zero_grad(set_to_none=True)
        total.backward()
        opt.step()

    return time_steps(step, warmup, reps)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--reps", type=int, default=7)
    ap.add_argument("--warmup", type=int, default=2)
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    ppo = ppo_bench(args.warmup, args.reps)
    amp = amp_bench(args.warmup, args.reps)
    print(json.dumps({
        "torch": torch.__version__, "threads": torch.get_num_threads(),
        "ppo": ppo, "ppo_samples_per_s": ppo["samples_per_s"],
        "amp": amp, "amp_samples_per_s": amp["samples_per_s"],
    }, indent=2))


if __name__ == "__main__":
    main()
