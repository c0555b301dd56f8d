#!/usr/bin/env bash
# Issue 30 confirmation: simple instance, seeds 1000-1099 (the block results/paper/simple ran on),
# 100 runs x 250 episodes. Usage: bash results/option-learning/confirm.sh NAME [train flags...]
set -euo pipefail
cd "$(dirname "$0")/../.."
name=$1; shift
out=results/option-learning/confirm/$name
if [ -f "$out/returns.npy" ]; then echo "$name: done"; exit 0; fi
if [ -d "$out" ]; then exec .venv/bin/skillchain train --resume "$out" --workers 2 --quiet; fi
exec .venv/bin/skillchain train --map pinball_simple_single --runs 100 --episodes 250 --seed 1000 \
  --workers 2 --checkpoint-every 25 --quiet --out "$out" "$@"
