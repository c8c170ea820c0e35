#!/bin/sh
# Carries the long comparisons and online runs on from one session to the next (issues 34
# and 35). A machine can be replaced between sessions, and runs/ and data/ go with it
# (sessions 12, 24 and 30 found them gone), so each step here starts from what the
# repository keeps: the grid files, the kept cells under experiments/results/, the
# behaviour policies and run snapshots under models/behaviour/. Run from the repository root
# after a build (`make build`, or `cargo test --no-run` as `make test` builds):
#
#   experiments/carry-on.sh datasets GRID...   make every missing dataset the grids' unfinished cells read
#   experiments/carry-on.sh start GRID...      run each grid's unfinished cells in the background
#   experiments/carry-on.sh online TASK...     resume TASK's online SAC run from its snapshot
#   experiments/carry-on.sh keep GRID...       copy the grids' newly finished cells and report into the repo
#
# GRID is a grid file (experiments/NAME.toml, or experiments/ablation/NAME.toml); its cells
# run under runs/NAME (runs/ablation/NAME), logged to runs/NAME.log, and are kept in
# experiments/results/NAME (experiments/results/ablation/NAME). A grid that borrows finished
# cells from other experiments names their kept folders in `# borrows: DIR` lines (relative
# to experiments/results/); `start` copies them in before the grid's own. Everything runs single-threaded
# at `nice -n 19` so builds and tests stay usable; NUNO_JOBS=N runs N of a grid's cells at
# once (one by default). Start a grid once per machine (a second runner of one grid would be
# refused each cell the first holds): `pgrep -af 'experiment run'` lists what runs.
set -eu

trainer=${NUNO_TRAINER:-$(cargo metadata --format-version 1 --no-deps |
    python3 -c 'import json, sys; print(json.load(sys.stdin)["target_directory"])')/release/nuno-trainer}
export LD_LIBRARY_PATH="$PWD/.mujoco/lib" MUJOCO_DYNAMIC_LINK_DIR="$PWD/.mujoco/lib" \
    NUNO_MJCF_DIR="$PWD/.mujoco/assets" RAYON_NUM_THREADS="${RAYON_NUM_THREADS:-1}"

# A grid's place under experiments/, without `.toml`: names its runs/ and results/ folders.
stem() {
    path=${1#./}
    path=${path#experiments/}
    echo "${path%.toml}"
}

# Copies the cells a grid borrows and its kept ones into the folder $2 (the runner skips them).
copy_finished() {
    for borrowed in $(sed -n 's|^# borrows: *||p' "$1"); do
        if [ ! -d "experiments/results/$borrowed" ]; then
            echo "carry-on: $1 borrows experiments/results/$borrowed, which is not there" >&2
            return 1
        fi
        cp -r "experiments/results/$borrowed/." "$2/"
    done
    kept=experiments/results/$(stem "$1")
    if [ -d "$kept" ]; then cp -r "$kept/." "$2/"; fi
}

# The data files (names under data/, without `.hdf5`) that a grid's unfinished cells read: a
# finished cell needs no data, so a fresh machine makes only these.
grid_datasets() {
    scratch=$(mktemp -d)
    copy_finished "$1" "$scratch"
    "$trainer" experiment status --grid "$1" --out "$scratch" >"$scratch/.status"
    python3 - "$1" "$scratch/.status" <<'PY'
import pathlib, sys, tomllib
grid, status = sys.argv[1:]
# Status lines: "  INDEX DATASET/METHOD/seed-N  STATE".
pending = {
    fields[1].split("/")[0]
    for fields in (line.split() for line in open(status))
    if len(fields) > 2 and fields[1].count("/") == 2 and not fields[2].startswith("done")
}
for row in tomllib.load(open(grid, "rb"))["datasets"]:
    if row["name"] in pending:
        print(pathlib.PurePath(row["file"]).stem)
PY
    rm -rf "$scratch"
}

# Makes data/NAME.hdf5 by the recipe its name says (the grid files' own commands, seed 0).
make_dataset() {
    name=$1
    case $name in
    neorl-*-*)
        rest=${name#neorl-}
        set -- --task "${rest%%-*}" --layout neorl --kind "${rest#*-}" --out "data/$name.npz" ;;
    *-random)
        set -- --task "${name%%-*}" --kind random --transitions 1000000 --out "data/$name.hdf5" ;;
    *-medium-replay)
        task=${name%%-*}
        if [ ! -d "models/behaviour/$task/run/transitions" ]; then
            echo "carry-on: data/$name.hdf5 needs $task's online run up to its medium step," \
                "which only the same kind of CPU re-creates (models/behaviour/README.md)" >&2
            return 1
        fi
        set -- --task "$task" --kind medium-replay --run "models/behaviour/$task/run" \
            --out "data/$name.hdf5" ;;
    *)
        set -- --task "${name%%-*}" --kind "${name#*-}" --out "data/$name.hdf5" ;;
    esac
    echo "carry-on: making data/$name.hdf5"
    nice -n 10 "$trainer" dataset generate "$@" --seed 0
}

# Makes every dataset it can, then fails if one could not be made.
datasets() {
    mkdir -p data
    missing=0
    for grid in "$@"; do
        for name in $(grid_datasets "$grid"); do
            [ -f "data/$name.hdf5" ] || make_dataset "$name" || missing=1
        done
    done
    return $missing
}

# A grid's cells run in runs/NAME; the kept ones are copied in first so the runner skips
# them, and the marker's time tells `keep` which cells finished after that.
start() {
    for grid in "$@"; do
        out=runs/$(stem "$grid")
        mkdir -p "$out"
        copy_finished "$grid" "$out"
        touch "$out/.carried-on"
        nohup nice -n 19 "$trainer" experiment run --grid "$grid" --out "$out" \
            --jobs "${NUNO_JOBS:-1}" >> "$out.log" 2>&1 &
        echo "carry-on: $grid running in $out (log $out.log, pid $!)"
    done
}

keep() {
    for grid in "$@"; do
        out=runs/$(stem "$grid")
        kept=$PWD/experiments/results/$(stem "$grid")
        [ -f "$out/.carried-on" ] || { echo "carry-on: $out was not started here" >&2; return 1; }
        mkdir -p "$kept"
        (cd "$out" && find . -name result.json -newer .carried-on -exec cp --parents {} "$kept/" \;)
        echo "carry-on: $(cd "$out" && find . -name result.json -newer .carried-on | wc -l) cells of $grid kept in $kept"
        # The grid's report (borrowed cells included) kept beside its cells, never older than
        # they; a grid with no finished cell yet has none.
        if [ -n "$(find "$out" -name result.json | head -n 1)" ]; then
            "$trainer" experiment report --grid "$grid" --out "$out" >/dev/null
            cp "$out/results.md" "$out/results.csv" "$out"/curves-*.svg "$kept/"
        fi
    done
}

# The run continues from its committed snapshot; its transitions past the medium step are not
# shipped, so the replay buffer is refilled with the snapshot policy's own steps, then and at
# every later resume of that run (the marker says its transitions have gaps).
online() {
    for task in "$@"; do
        run=runs/$task-sac
        if [ ! -d "$run" ]; then
            cp -r "models/behaviour/$task/run" "$run"
            touch "$run/.from-snapshot"
        fi
        refill=""
        if [ -f "$run/.from-snapshot" ]; then refill="--refill 10000"; fi
        # shellcheck disable=SC2086
        nohup nice -n 19 "$trainer" collect online-sac --task "$task" --steps 1000000 --seed 0 \
            --out "$run" --resume $refill >> "$run.log" 2>&1 &
        echo "carry-on: $task's online run resumed in $run (log $run.log, pid $!)"
    done
}

command=${1:-}
[ $# -gt 0 ] && shift
case $command in
datasets | start | keep | online) "$command" "$@" ;;
*)
    sed -n '9,12p' "$0" >&2
    exit 2
    ;;
esac
