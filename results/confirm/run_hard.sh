#!/bin/bash
# Issue 52's confirmation block on the hard instance: seeds 5000-5099, 100 x 250, in seed blocks
# that each finish inside one session (a hard arm of 100 agents costs 1 to 9 core-hours).
# By the seed contract agents [a, b) of a run seeded 5000 are the run of b - a agents seeded
# 5000 + a, bit for bit, so the blocks are the arm; results/confirm/merge_hard.py lays them out
# as one run per arm. Each block is one process at 1 thread; two lanes use the two cores.
#   bash results/confirm/run_hard.sh OUT LANE_JOBS...     e.g. flat:0-25 default:0-10
# A job is ARM:A-B. Resumable: a finished block (run_info.json) is skipped, one with
# checkpoints resumes. No choice is made from this block (see README.md).
cd "$(dirname "$0")/../.."
OUT=${1:?OUT}
shift
mkdir -p "$OUT"
source results/run_arm.sh
# The arms' flags are the simple block's (results/confirm/run.sh), chosen on screening seeds.
FAITHFUL="--preset paper --initiation-start biased --initiation-bias 2 --initiation-centered"
for job in "$@"; do
  arm=${job%%:*}; span=${job#*:}; a=${span%-*}; b=${span#*-}
  # (a checkpoint every 5 episodes: the slowest of 25 hard agents took 45 minutes to reach its
  # 7th episode, and a run stopped with the session keeps only what its last checkpoint holds)
  SC=".venv/bin/skillchain train --map pinball_hard_two_starts --runs $((b - a)) --episodes 250 --seed $((5000 + a)) --threads 1 --quiet --checkpoint-every 5"
  name="$arm/parts/$a-$b"
  mkdir -p "$OUT/$arm/parts"
  case $arm in
    flat) run "$name" --agent flat ;;
    default) run "$name" --agent skill-chaining ;;
    given-options) run "$name" --agent given-options --options "$OUT/default/parts/$a-$b/options.pt" --options-agent each ;;
    paper) run "$name" --agent skill-chaining --preset paper ;;
    paper-b2) run "$name" --agent skill-chaining $FAITHFUL ;;
    no-chaining) run "$name" --agent skill-chaining --slots 1 ;;  # control (a), agents 0-49
    random-subgoals) run "$name" --agent skill-chaining --subgoals random ;;  # (b), 0-49
    flat-o6) run "$name" --agent flat --order 6 --alpha "${O6_ALPHA:?set O6_ALPHA (screened: results/controls/screen_hard.sh)}" ;;
    *) echo "unknown arm $arm" >&2; exit 2 ;;
  esac
done
