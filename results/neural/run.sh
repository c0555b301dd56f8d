#!/usr/bin/env bash
# Issue 31's pilots: flat against skill chaining, linear and neural, on Gymnasium envs and Pinball.
#   [SEED=1000] bash results/neural/run.sh ENV NAME EPISODES [train flags...]
# ENV: a Gymnasium id (MountainCar-v0, Acrobot-v1) or a Pinball map (pinball_*); 10 runs,
# seeds SEED..SEED+9 (default 0-9: the pilots and screens; 1000-1009: the reported runs after
# the ninth session's screen), one process (P = 10 agents batched). FOLDER: the folder under
# results/neural/ (default ENV; the ninth session's seed-1000 runs are in ENV-1000).
set -euo pipefail
cd "$(dirname "$0")/../.."
env=$1 name=$2 episodes=$3; shift 3
case $env in
  pinball_*) where=(--map "$env") ;;
  *) where=(--env "gymnasium:$env") ;;
esac
out=results/neural/${FOLDER:-$env}/$name
if [ -f "$out/returns.npy" ]; then echo "$env/$name: done"; exit 0; fi
if [ -d "$out" ]; then exec .venv/bin/skillchain train --resume "$out" --quiet; fi
exec .venv/bin/skillchain train "${where[@]}" --runs 10 --episodes "$episodes" --seed "${SEED:-0}" \
  --checkpoint-every 10 --quiet --out "$out" "$@"
