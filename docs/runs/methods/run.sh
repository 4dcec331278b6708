#!/usr/bin/env bash
# Every method of configs/methods/ at 5 % of its budget (~50 iterations, ~205k samples each), then the tables.
set -u
# (run from the repository root, after `cargo build --release -p lhm-cli`, with target/release on PATH;
# eighth session, 2026-11-25, 2 cores, the clean-clone CI beside it from the fourth method on)
for m in lhm no-rr no-amp e2e-rl curriculum-rl hierarchical-rl; do
  echo "=== $m $(date -u +%FT%TZ)"
  lhm pipeline --config configs/methods/$m.toml --runs-dir /work/runs-methods --budget-scale 0.05 2>&1 | grep -v "^iteration" 
done
echo "=== tables $(date -u +%FT%TZ)"
lhm tables --runs /work/runs-methods --seeds 1 --limit 10 -o /work/runs-methods/tables 2>&1
echo "=== done $(date -u +%FT%TZ)"
