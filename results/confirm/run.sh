#!/bin/bash
# Issue 52's confirmation block: the simple instance, seeds 5000-5099 (never used for a
# choice), 100 x 250, every arm the report shows, each once, one after another at nice 10;
# resumable (a finished arm is skipped, one with checkpoints resumes).
#   bash results/confirm/run.sh [OUT] [ARM ...]      (default OUT: runs/confirm-simple; all arms)
# Choices made before this block, on screening seeds 0-99 (results/faithful, results/controls):
# the faithful reading's intercept (2, of 2 and 4), the richer flat agents' step sizes.
cd "$(dirname "$0")/../.."
OUT=${1:-runs/confirm-simple}
shift || true
mkdir -p "$OUT"
SC=".venv/bin/skillchain train --map pinball_simple_single --runs 100 --episodes 250 --seed 5000 --quiet"
source results/run_arm.sh
FAITHFUL="--preset paper --initiation-start biased --initiation-bias 2 --initiation-centered"
arm() {
  case $1 in
    flat) run flat --agent flat ;;
    default) run default --agent skill-chaining ;;
    given-options) run given-options --agent given-options --options "$OUT/default/options.pt" --options-agent each ;;
    no-chaining) run no-chaining --agent skill-chaining --slots 1 ;;
    random-subgoals) run random-subgoals --agent skill-chaining --subgoals random ;;
    paper) run paper --agent skill-chaining --preset paper ;;
    paper-b2) run paper-b2 --agent skill-chaining $FAITHFUL ;;
    flat-o5) run flat-o5 --agent flat --order 5 --alpha "${O5_ALPHA:?set O5_ALPHA (screened)}" ;;
    flat-o6) run flat-o6 --agent flat --order 6 --alpha "${O6_ALPHA:?set O6_ALPHA (screened)}" ;;
    *) echo "unknown arm $1" >&2; exit 2 ;;
  esac
}
ARMS=("$@")
[ ${#ARMS[@]} -eq 0 ] && ARMS=(default flat given-options no-chaining random-subgoals paper-b2 paper flat-o5 flat-o6)
for a in "${ARMS[@]}"; do arm "$a"; done
