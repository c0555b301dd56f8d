#!/bin/bash
# Issue 52's controls, screened on seeds 0-99 (the simple instance, 100 x 250, one arm after
# another on one core; resumable: an arm with checkpoints resumes, a finished arm is skipped).
#   bash results/controls/screen.sh [OUT]      (default OUT: runs/controls-screen)
# (a) no chaining: one slot, so discovery stops after its first option, the goal option;
# (b) random subgoals: the same slots aimed at random discs instead of learned sets;
# (c) a richer flat agent: Fourier order 5 (step sizes 0.00025-0.002: the grid grew upwards,
#     0.001 was its best at first) and 6 (0.00025-0.0005; 0.001 ran away).
cd "$(dirname "$0")/../.."
OUT=${1:-runs/controls-screen}
mkdir -p "$OUT"
SC=".venv/bin/skillchain train --map pinball_simple_single --runs 100 --episodes 250 --seed 0 --quiet"
source results/run_arm.sh
run no-chaining --agent skill-chaining --slots 1
run random-subgoals --agent skill-chaining --subgoals random
for alpha in 0.001 0.0005 0.00025 0.002; do
  run "flat-o5-a$alpha" --agent flat --order 5 --alpha "$alpha"
done
# Order 6 (2,401 features): at 0.001 its agents' episodes ran to 100,000-290,000 steps by
# episodes 90-137 (not finished after 23 minutes, stopped); smaller steps only.
for alpha in 0.0005 0.00025; do
  run "flat-o6-a$alpha" --agent flat --order 6 --alpha "$alpha"
done
