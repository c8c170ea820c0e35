#!/bin/sh
# Issue 34, item 3: one table across every dataset nuno has compared on, laid out as the
# paper's Tables 1 and 2 (dataset rows, method columns, mean ± std of the best scores, the
# paper's figure beside each), from the kept cells under experiments/results/. Each dataset's
# cells come from one experiment: hopper-medium's from the faithful comparison (the behaviour
# comparison's ran on the older hopper-medium bytes), medium-replay and medium-expert from
# the behaviour comparison; halfcheetah's NUNO cells that the pose-drift ablations ran are the
# comparisons' own (their grids borrow them). Run from the repository root after a build:
#   experiments/paper-tables.sh [path to nuno-trainer]
set -eu
trainer=${1:-target/release/nuno-trainer}
r=experiments/results
set -- \
    "$r/hopper-faithful-comparison" \
    "$r/ablation/hopper-random-paper" \
    "$r/hopper-baselines-comparison" \
    "$r/hopper-behaviour-comparison/hopper-medium-replay" \
    "$r/hopper-behaviour-comparison/hopper-medium-expert" \
    "$r/neorl-hopper-comparison" \
    "$r/d4rl-walker2d-halfcheetah-comparison" \
    "$r/ablation/halfcheetah-random-pose-drift" \
    "$r/neorl-walker2d-halfcheetah-comparison" \
    "$r/ablation/neorl-halfcheetah-low-pose-drift"
args=""
for folder in "$@"; do
    # A grid whose first cell has not finished has no folder yet.
    if [ -d "$folder" ]; then args="$args --results $folder"; fi
done
# shellcheck disable=SC2086
"$trainer" experiment table $args --out "$r/paper-tables.md"
