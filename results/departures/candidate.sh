#!/bin/bash
# Issue 52, item 4, step 3: the candidate default (the paper's values, and the departures the
# leave-one-out screen found needed, 3 at most: table.py prints them) on the same screening
# seeds 0-49, 50 x 250, the simple instance. Resumable.
#   bash results/departures/candidate.sh OUT NAME --preset paper --end-outside-set learned ...
cd "$(dirname "$0")/../.."
OUT=${1:?OUT}
NAME=${2:?NAME}
shift 2
mkdir -p "$OUT"
SC=".venv/bin/skillchain train --agent skill-chaining --map pinball_simple_single --runs 50 --episodes 250 --seed 0 --threads 1 --quiet"
source results/run_arm.sh
run "$NAME" "$@"
