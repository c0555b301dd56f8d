#!/usr/bin/env bash
# Issue 30 screen: simple instance, seeds 0-19 (screening only, never the reported evidence),
# 20 runs x 250 episodes. Usage: bash results/option-learning/screen.sh NAME [train flags...]
set -euo pipefail
cd "$(dirname "$0")/../.."
name=$1; shift
out=results/option-learning/screen/$name
if [ -f "$out/returns.npy" ]; then echo "$name: done"; exit 0; fi
if [ -d "$out" ]; then exec .venv/bin/skillchain train --resume "$out" --workers 2 --quiet; fi
exec .venv/bin/skillchain train --map pinball_simple_single --runs 20 --episodes 250 --seed 0 \
  --workers 2 --checkpoint-every 25 --quiet --out "$out" "$@"
