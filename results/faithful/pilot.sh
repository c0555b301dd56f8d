#!/bin/bash
# Issue 52 pilot: the faithful reading on screening seeds 0-9, 10 x 250, simple instance.
cd /work/main
SC=".venv/bin/skillchain train --map pinball_simple_single --runs 10 --episodes 250 --seed 0 --quiet"
run() { name=$1; shift; [ -f results/faithful/screen-simple-10x250/$name/returns.npy ] && return; nice -n 10 $SC "$@" --out results/faithful/screen-simple-10x250/$name --resume >/dev/null 2>&1 || nice -n 10 $SC "$@" --out results/faithful/screen-simple-10x250/$name > results/faithful/screen-simple-10x250/$name.log 2>&1; }
run flat --agent flat
run default --agent skill-chaining
run paper --agent skill-chaining --preset paper
for B in 2 4 8; do run paper-b$B --agent skill-chaining --preset paper --initiation-start biased --initiation-bias $B --initiation-centered; done
echo done > results/faithful/screen-simple-10x250/pilot.done
