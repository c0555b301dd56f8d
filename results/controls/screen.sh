#!/bin/bash
# Issue 52's controls, screened on seeds 0-99 (the simple instance, 100 x 250, one arm after
# another on one core; resumable: an arm with checkpoints resumes, a finished arm is skipped).
#   bash results/controls/screen.sh [OUT]      (default OUT: runs/controls-screen)
# (a) no chaining: one slot, so discovery stops after its first option, the goal option;
# (b) random subgoals: the same slots aimed at random discs instead of learned sets;
# (c) a richer flat agent: Fourier order 5 and 6, step size screened over three values.
cd "$(dirname "$0")/../.."
OUT=${1:-runs/controls-screen}
mkdir -p "$OUT"
SC=".venv/bin/skillchain train --map pinball_simple_single --runs 100 --episodes 250 --seed 0 --quiet"
source results/run_arm.sh
run no-chaining --agent skill-chaining --slots 1
for order in 5 6; do
  for alpha in 0.001 0.0005 0.00025; do
    run "flat-o$order-a$alpha" --agent flat --order "$order" --alpha "$alpha"
  done
done
# (b) random subgoals: the goal option, and one random disc per other slot in place of the chain
run random-subgoals --agent skill-chaining --subgoals random
