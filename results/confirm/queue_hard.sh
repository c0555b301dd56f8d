#!/bin/bash
# Everything left of issue 52's hard confirmation block, in the issue's order, on two lanes (one
# process each, one thread each), resumable: run it again after any stop and it goes on where
# its parts' checkpoints are (a finished part is skipped). Parts of 25 agents, so that one
# finishes inside a session (run_hard.sh; the seed contract makes the parts the arm).
#   bash results/confirm/queue_hard.sh            (OUT: results/confirm/hard-5000x100)
# Order (issue 52, "Priority, for the compute"): the confirmation arms (the default, then given
# options from its trees, the faithful reading, the paper preset), then the hard controls: the
# order-6 flat agent's step-size screen on seeds 0-49 and its confirmation (O6_ALPHA, chosen by
# the screen's rule, must be set for that lane's last jobs), no chaining and random subgoals on
# agents 0-49 of the block. Flat (100 x 250) is done.
cd "$(dirname "$0")/../.."
OUT=${1:-results/confirm/hard-5000x100}
parts() { for span in 0-25 25-50 50-75 75-100; do echo "$1:$span"; done; }
lane1=($(parts default) $(parts given-options) no-chaining:0-25 no-chaining:25-50)
lane2=($(parts paper-b2) $(parts paper) random-subgoals:0-25 random-subgoals:25-50)
bash results/confirm/run_hard.sh "$OUT" "${lane1[@]}" &
bash results/confirm/run_hard.sh "$OUT" "${lane2[@]}" &
wait
# The order-6 control: its screen (2 arms of 50 x 250 on seeds 0-49), then, with O6_ALPHA set
# from it, flat-o6 on the block's 100 agents.
bash results/controls/screen_hard.sh
if [ -n "${O6_ALPHA:-}" ]; then
  bash results/confirm/run_hard.sh "$OUT" $(parts flat-o6)
else
  echo "flat-o6: set O6_ALPHA from results/controls/screen-hard-50x250 (the screen's rule) and run again"
fi
