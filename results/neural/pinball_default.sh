#!/usr/bin/env bash
# Issue 53's Pinball comparison: neural skill chaining under the working default against neural
# flat (the same learner and preset with --max-branching 0), the simple instance, 10 runs
# (seeds 1000-1009) x 100 episodes, the learner flags of results/neural/fair.sh. Resumable: an
# arm with returns.npy is skipped, one with checkpoints resumes.
#   bash results/neural/pinball_default.sh
set -euo pipefail
cd "$(dirname "$0")/../.."
NEURAL=(--top-head mlp --option-head mlp --initiation mlp --epsilon 0.05 --epsilon-init 1
        --annealing-steps 10000)
for arm in flat-neural sc-neural; do
  out=results/neural/pinball_simple_single-default/$arm
  if [ -f "$out/returns.npy" ]; then continue; fi
  if [ -d "$out/checkpoints" ]; then
    nice -n 10 .venv/bin/skillchain train --resume "$out" --quiet --threads 1
    continue
  fi
  extra=(); [ "$arm" = flat-neural ] && extra=(--max-branching 0)
  nice -n 10 .venv/bin/skillchain train --map pinball_simple_single --agent skill-chaining \
    --runs 10 --episodes 100 --seed 1000 --checkpoint-every 5 --keep-checkpoints 3 --quiet \
    --out "$out" \
    --overwrite --threads 1 "${NEURAL[@]}" "${extra[@]}"
done
