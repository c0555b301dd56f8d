#!/usr/bin/env bash
# Issue 30's option-learning runs on the simple or hard instance, 250 episodes, two workers, checkpoints
# every 25 episodes (WORKERS=1 for one process); a variant whose folder exists but has no
# returns.npy is resumed.
#   bash results/option-learning/run.sh screen NAME [train flags...]   # seeds 0-19, 20 runs
#   bash results/option-learning/run.sh confirm NAME [train flags...]  # seeds 1000-1099, 100 runs
#   screen-hard / confirm-hard: the same blocks on pinball_hard_two_starts
#   bash results/option-learning/run.sh replicate NAME [train flags...]  # seeds 7000-7099, 100 x 60
set -euo pipefail
cd "$(dirname "$0")/../.."
block=$1 name=$2; shift 2
map=pinball_simple_single episodes=250 every=25
case $block in
  screen) runs=20 seed=0 ;;  # screening only, never the reported evidence
  confirm) runs=100 seed=1000 ;;  # the block results/paper/simple ran on
  screen-hard) runs=20 seed=0 map=pinball_hard_two_starts ;;
  confirm-hard) runs=100 seed=1000 map=pinball_hard_two_starts ;;  # results/paper/hard: 1000-1099
  replicate) runs=100 seed=7000 episodes=60 every=20 ;;  # fresh: no run had used these seeds
  *) echo "run.sh: block must be screen, confirm, screen-hard, confirm-hard or replicate, got '$block'" >&2
     exit 2 ;;
esac
out=results/option-learning/$block/$name
if [ -f "$out/returns.npy" ]; then echo "$name: done"; exit 0; fi
if [ -d "$out" ]; then exec .venv/bin/skillchain train --resume "$out" --workers "${WORKERS:-2}" --quiet; fi
exec .venv/bin/skillchain train --map "$map" --runs "$runs" --episodes "$episodes" \
  --seed "$seed" --workers "${WORKERS:-2}" --checkpoint-every "$every" --quiet --out "$out" "$@"
