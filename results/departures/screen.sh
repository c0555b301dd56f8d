#!/bin/bash
# Issue 52, item 4: which of the default's departures from the paper's stated values does it
# need? Each arm is the library's default with ONE field put back to the paper's value
# (leave one out), on screening seeds 0-49 (the simple instance, 50 x 250). The default itself
# on these seeds is agents 0-49 of results/faithful/screen-simple-100x250/default (by the seed
# contract, bit for bit the 50-agent run seeded 0), so it is not run again.
#   bash results/departures/screen.sh OUT ARM...     (resumable; a finished arm is skipped)
cd "$(dirname "$0")/../.."
OUT=${1:?OUT}
shift
mkdir -p "$OUT"
SC=".venv/bin/skillchain train --agent skill-chaining --map pinball_simple_single --runs 50 --episodes 250 --seed 0 --threads 1 --quiet"
source results/run_arm.sh
for arm in "$@"; do
  case $arm in
    failure-bootstrap) run "$arm" --failure-bootstrap decision ;;
    end-outside-set) run "$arm" --end-outside-set off ;;
    option-alpha) run "$arm" --option-alpha 0.0005 ;;
    policy-start) run "$arm" --policy-start zero ;;
    value-start) run "$arm" --value-start max-sample ;;
    gestation) run "$arm" --gestation 10 ;;
    gestation-positives) run "$arm" --gestation-positives 0 ;;
    initiation-start) run "$arm" --initiation-start everything ;;
    initiation-constrain) run "$arm" --initiation-constrain learned ;;
    *) echo "unknown arm $arm" >&2; exit 2 ;;
  esac
done
