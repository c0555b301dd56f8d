#!/usr/bin/env bash
# Issue 53's run on the suspected cause at the fair comparison's size: neural skill chaining
# under the default with the option time limit at 50 steps instead of 250 (--max-option-steps
# 50), the learner flags and seeds of fair.sh (30 runs, seeds 1000-1029), for the episodes
# neural flat needs to plateau by the issue's rule (Acrobot: 100). Compared with fair.sh's
# sc-neural and flat-neural over the same episodes. Resumable like fair.sh.
#   bash results/neural/fair_cause.sh ENV EPISODES      e.g. Acrobot-v1 100
set -euo pipefail
cd "$(dirname "$0")/../.."
env=${1:?ENV}; episodes=${2:?EPISODES}
NEURAL=(--top-head mlp --option-head mlp --initiation mlp --epsilon 0.05 --epsilon-init 1
        --annealing-steps 10000)
out=results/neural/fair/$env/sc-neural-o50
if [ -f "$out/returns.npy" ]; then exit 0; fi
if [ -d "$out/checkpoints" ]; then
  exec nice -n 10 .venv/bin/skillchain train --resume "$out" --quiet
fi
exec nice -n 10 .venv/bin/skillchain train --env "gymnasium:$env" --agent skill-chaining \
  --runs 30 --episodes "$episodes" --seed 1000 --checkpoint-every 10 --keep-checkpoints 3 \
  --quiet --out "$out" \
  --overwrite --max-option-steps 50 "${NEURAL[@]}"
