#!/usr/bin/env bash
# qbricks `exact` against yt 4.4's AMR volume render on issue 33's independent layout
# (three nested boxes, docs/bench/layouts/independent.json), the benchmark camera of
# speed_goals.sh, SIZE² pixels, rounds alternating between the two, THREADS threads each.
#
#   docs/bench/yt_compare.sh [WORK] [ROUNDS] [THREADS] [SIZE]     (from the repository root,
#   after `cargo build --release --workspace`; needs python3-openvdb and network for pip)
#
# yt gets Q per level from the same velocity (docs/bench/yt/levels.py: central differences
# on each box, as the bake's default stencil inside a box) and renders one narrow Gaussian
# layer at the iso value; qbricks renders its iso-surface. Each yt round renders REPEATS
# times in one process and reports the median (the first render includes yt's set-up).
set -euo pipefail
WORK=${1:-/tmp/yt_compare}
ROUNDS=${2:-3}
THREADS=${3:-2}
SIZE=${4:-1024}
REPEATS=3
ROOT=$(pwd)
BIN="$ROOT/target/release"
for exe in "$BIN/qbricks-bake" "$BIN/qbricks-view" "$BIN/qbricks-lab"; do
    [[ -x $exe ]] || { echo "missing $exe: cargo build --release --workspace" >&2; exit 2; }
done
/usr/bin/python3 -c 'import pyopenvdb' 2>/dev/null \
    || { echo "missing pyopenvdb: apt-get install python3-openvdb" >&2; exit 2; }
mkdir -p "$WORK"
if [[ ! -x $WORK/venv/bin/python ]]; then
    python3 -m venv "$WORK/venv"
    "$WORK/venv/bin/pip" install -q --disable-pip-version-check "yt==4.4.*" numpy
fi
cd "$WORK"
[[ -f independent.vdb ]] || "$BIN/qbricks-lab" synth wake -o independent.vdb \
    --boxes "$ROOT/docs/bench/layouts/independent.json" >/dev/null
"$BIN/qbricks-bake" bake independent.vdb -o independent.qbk --quiet
/usr/bin/python3 "$ROOT/docs/bench/yt/levels.py" independent.vdb levels.npz
CAM=(--eye 3.5,-4.5,2 --look-at 2.3,0,0 --up 0,0,1 --fov 30 --iso 0.05)
for r in $(seq "$ROUNDS"); do
    yt=$(OMP_NUM_THREADS=$THREADS "$WORK/venv/bin/python" "$ROOT/docs/bench/yt/render.py" \
        levels.npz "$SIZE" "$REPEATS" "yt_$SIZE.png" 2>/dev/null | awk '/^yt_ms/{print $NF}')
    qb=$("$BIN/qbricks-view" render independent.qbk "${CAM[@]}" --width "$SIZE" --height "$SIZE" \
        --strategy exact --threads "$THREADS" --repeat 5 --json -o "qbricks_$SIZE.png" |
        python3 -c 'import json, sys; print(round(json.load(sys.stdin)["ms"], 1))')
    echo "round $r: yt $yt ms, qbricks exact $qb ms, ratio $(python3 -c "print(round($yt / $qb, 1))")"
done
