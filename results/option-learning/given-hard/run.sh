#!/usr/bin/env bash
# Given options on the hard instance, seeds 0-9, 25 episodes: does a bigger tree start nearer
# the discoverers' final level, and does ending executions where they leave their set cost the
# start? Agent p of each run takes discoverer p's options (screen seeds 0-9, never reported as
# the study). WORKERS=1 by default (it shares the machine with the slot pilot).
#   bash results/option-learning/given-hard/run.sh NAME OPTIONS_FOLDER [train flags...]
set -euo pipefail
cd "$(dirname "$0")/../../.."
name=$1 from=$2; shift 2
out=results/option-learning/given-hard/$name
if [ -f "$out/returns.npy" ]; then echo "$name: done"; exit 0; fi
if [ -d "$out" ]; then exec .venv/bin/skillchain train --resume "$out" --workers "${WORKERS:-1}" --quiet; fi
exec .venv/bin/skillchain train --agent given-options --map pinball_hard_two_starts --runs 10 \
  --episodes 25 --seed 0 --workers "${WORKERS:-1}" --checkpoint-every 5 --quiet --out "$out" \
  --options "$from/options.pt" --options-agent each "$@"
