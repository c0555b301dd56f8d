#!/usr/bin/env bash
# Issue 53's fair comparison: neural skill chaining under the working default (its starts
# fitted in the heads' last layers) against neural flat under the same preset with no options
# (--max-branching 0), 30 runs (seeds 1000-1029), 300 episodes (the issue's most; the plateau
# of neural flat is read from the arrays: its last 25-episode mean inside the previous
# window's 95% interval). Each env's goal is its own (skillchain_torch/options/goals.py).
# Resumable: an arm with returns.npy is skipped, one with checkpoints resumes.
#   bash results/neural/fair.sh ENV...      e.g. Acrobot-v1 MountainCar-v0 LunarLander-v3
set -euo pipefail
cd "$(dirname "$0")/../.."
NEURAL=(--top-head mlp --option-head mlp --initiation mlp --epsilon 0.05 --epsilon-init 1
        --annealing-steps 10000)
for env in "$@"; do
  for arm in flat-neural sc-neural; do
    out=results/neural/fair/$env/$arm
    if [ -f "$out/returns.npy" ]; then continue; fi
    if [ -d "$out/checkpoints" ]; then
      nice -n 10 .venv/bin/skillchain train --resume "$out" --quiet
      continue
    fi
    extra=(); [ "$arm" = flat-neural ] && extra=(--max-branching 0)
    nice -n 10 .venv/bin/skillchain train --env "gymnasium:$env" --agent skill-chaining \
      --runs 30 --episodes 300 --seed 1000 --checkpoint-every 10 --keep-checkpoints 3 --quiet \
      --out "$out" \
      --overwrite "${NEURAL[@]}" "${extra[@]}"
  done
done
