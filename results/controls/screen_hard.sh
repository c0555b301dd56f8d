#!/bin/bash
# Issue 52's control (c) on the hard instance: a richer flat agent, Fourier order 6 (2,401
# features; order 5 is already the hard instance's flat baseline, the paper's), its step size
# screened on seeds 0-49 (50 x 250), one arm after another on one core, resumable. The choice
# rule, fixed before any arm runs (as the simple instance's): the step size with the highest
# mean return over all 250 episodes. The chosen one then runs once on the confirmation block
# (results/confirm/run_hard.sh, seeds 5000-5099, 100 x 250).
#   bash results/controls/screen_hard.sh [OUT]    (default OUT: results/controls/screen-hard-50x250)
# Step sizes: the paper's 0.0005 at order 5 and half of it; on the simple instance order 6 ran
# away at 0.001 (episodes of 100,000+ steps), so the grid starts below it.
cd "$(dirname "$0")/../.."
OUT=${1:-results/controls/screen-hard-50x250}
mkdir -p "$OUT"
SC=".venv/bin/skillchain train --map pinball_hard_two_starts --runs 50 --episodes 250 --seed 0 --threads 1 --quiet"
source results/run_arm.sh
for alpha in 0.0005 0.00025; do
  run "flat-o6-a$alpha" --agent flat --order 6 --alpha "$alpha"
done
