#!/bin/bash
# Issue 52: the faithful reading (paper-b2 of screen100.sh) with one of the paper's own
# mechanisms against a runaway made to act, on the same screening seeds 0-99 (100 x 250, one
# core, resumable). Failures lowering Q(s, o): a timed-out execution's SMDP target bootstraps
# on the best primitive at s' instead of the next decision (whose value is an option's own
# optimistic start when the agent chains options: then a failure lowers nothing).
#   bash results/faithful/mechanisms.sh [OUT]      (default OUT: runs/faithful-screen100)
cd "$(dirname "$0")/../.."
OUT=${1:-runs/faithful-screen100}
mkdir -p "$OUT"
SC=".venv/bin/skillchain train --map pinball_simple_single --runs 100 --episodes 250 --seed 0 --quiet"
FAITHFUL="--agent skill-chaining --preset paper --initiation-start biased --initiation-bias 2 --initiation-centered"
source results/run_arm.sh
run paper-b2-failure-primitives $FAITHFUL --failure-bootstrap primitives
