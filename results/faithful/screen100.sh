#!/bin/bash
# Issue 52's screen of the faithful reading at 100 runs: simple instance, screening seeds 0-99,
# 100 x 250, one arm after another on one core (resumable: an arm with checkpoints resumes).
#   bash results/faithful/screen100.sh [OUT]      (default OUT: runs/faithful-screen100)
cd "$(dirname "$0")/../.."
OUT=${1:-runs/faithful-screen100}
mkdir -p "$OUT"
SC=".venv/bin/skillchain train --map pinball_simple_single --runs 100 --episodes 250 --seed 0 --quiet"
source results/run_arm.sh
run flat --agent flat
run paper-b2 --agent skill-chaining --preset paper --initiation-start biased --initiation-bias 2 --initiation-centered
run paper-b4 --agent skill-chaining --preset paper --initiation-start biased --initiation-bias 4 --initiation-centered
run default --agent skill-chaining
run paper --agent skill-chaining --preset paper
