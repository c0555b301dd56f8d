#!/bin/bash
# Sourced by the study scripts: `run NAME FLAGS...` trains one arm as `$SC FLAGS --out $OUT/NAME`
# at nice 10, resumable: a finished arm (run_info.json) is skipped, one with checkpoints resumes.
# The sourcing script sets OUT and SC (the shared `skillchain train ...` command).
run() {
  name=$1; shift
  [ -f "$OUT/$name/run_info.json" ] && return
  if [ -d "$OUT/$name/checkpoints" ]; then
    nice -n 10 .venv/bin/skillchain train --resume "$OUT/$name" --quiet >> "$OUT/$name.log" 2>&1
  else
    nice -n 10 $SC "$@" --out "$OUT/$name" --overwrite > "$OUT/$name.log" 2>&1
  fi
}
