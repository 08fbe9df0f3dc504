#!/usr/bin/env bash
# The speed goals of BENCHMARKS.md ("Speed: structure, open, bake, frames"), measured side
# by side in one run on both benchmark layouts: the n0-128 wake (`synth wake --n0 128
# --levels 3`, file wake128) and issue 33's independent layout (`synth wake --boxes
# docs/bench/layouts/independent.json`, file independent): bake against `vdb_print -l`,
# `open_ms` with and without the checksum, `exact` frames at 1024² and 256² against
# `vdb_render` on a narrow-band level set of the same surface, the other iso strategies at
# 1024², and the file's structure against its field values. Run from the repository root
# after `cargo build --release --workspace --examples`; needs vdb_print, vdb_render and
# vdb_tool (Debian: libopenvdb-tools).
#
#   docs/bench/speed_goals.sh [WORKDIR=/tmp/speed_goals] [ROUNDS=5] [THREADS=2]
#
# FILES="wake128" (or "independent") measures one layout only. Measurements are named
# FILE:WHAT (wake128:exact_1024).
#
# BEFORE=DIR compares with the qbricks-bake and qbricks-view in DIR (an older build): every
# measurement then alternates between the two builds, each on a file it baked itself.
# Prints one line per measurement and round, then medians.
set -euo pipefail

WORK=${1:-/tmp/speed_goals}
ROUNDS=${2:-5}
THREADS=${3:-2}
ROOT=$(pwd)
NOW="$ROOT/target/release"
EXPORT="$ROOT/target/release/examples/qbk_to_vdb"
LAYOUTS="$ROOT/docs/bench/layouts"
read -r -a FILES <<<"${FILES:-wake128 independent}"
for exe in "$NOW/qbricks-bake" "$NOW/qbricks-view" "$NOW/qbricks-lab" "$EXPORT"; do
    [[ -x $exe ]] || { echo "missing $exe: cargo build --release --workspace --examples" >&2; exit 2; }
done
for tool in vdb_print vdb_render vdb_tool; do
    command -v $tool >/dev/null || { echo "missing $tool: apt-get install libopenvdb-tools" >&2; exit 2; }
done
BUILDS=(now)
declare -A BIN=([now]="$NOW")
if [[ -n ${BEFORE:-} ]]; then
    BUILDS=(before now)
    BIN[before]=$BEFORE
fi
mkdir -p "$WORK"
cd "$WORK"
LOG=$WORK/measurements.txt
: >"$LOG"
note() { echo "$*" | tee -a "$LOG"; }

# The camera of BENCHMARKS.md (vdb_render's -fov is horizontal, ours vertical: equal for
# a square image).
EYE=3.5,-4.5,2; LOOK=2.3,0,0; UP=0,0,1; FOV=30; ISO=0.05
QB_CAM=(--eye $EYE --look-at $LOOK --up $UP --fov $FOV --iso $ISO --threads "$THREADS")

# The two layouts, each synthesised once into WORKDIR.
synth() {
    case $1 in
        wake128) "$NOW/qbricks-lab" synth wake -o wake128.vdb --n0 128 --levels 3 ;;
        independent) "$NOW/qbricks-lab" synth wake -o independent.vdb --boxes "$LAYOUTS/independent.json" ;;
        *) echo "unknown file $1 (expected wake128 or independent)" >&2; exit 2 ;;
    esac
}
for f in "${FILES[@]}"; do
    [[ -f $f.vdb ]] || synth "$f"
    for b in "${BUILDS[@]}"; do
        [[ -f ${f}_$b.qbk ]] || "${BIN[$b]}/qbricks-bake" bake "$f.vdb" -o "${f}_$b.qbk" --quiet
    done
    if [[ ! -f ls_$f.vdb ]]; then
        "$EXPORT" "${f}_now.qbk" "q_$f.vdb" "fog_$f.vdb" --iso $ISO
        vdb_tool -quiet -read "q_$f.vdb" -iso2ls iso=-$ISO width=3 -write "ls_$f.vdb"
    fi
done

json() { python3 -c "import json,sys; print('%.1f' % json.load(sys.stdin)['$1'])"; }
secs() { local t0; t0=$(date +%s.%N); "$@" >/dev/null 2>&1; echo "$(date +%s.%N) - $t0" | bc; }
vdb_ms() { vdb_render "ls_$1.vdb" /tmp/speed_goals_vdb.png -shader diffuse -res "${2}x$2" \
    -translate $EYE -lookat $LOOK -up $UP -fov $FOV -cpus "$THREADS" -v 2>&1 |
    awk '/ray-tracing/ {r=1} r && /completed in/ {print $(NF-1) * 1000; exit}'; }

note "load before: $(uptime)"
for f in "${FILES[@]}"; do
    for b in "${BUILDS[@]}"; do
        note "$f $b structure: $("${BIN[$b]}/qbricks-view" info "${f}_$b.qbk" | grep -o '[0-9]* bricks; [0-9]* regions ([0-9]* brick refs); KD-tree [0-9]* nodes, [0-9]* leaves, depth [0-9]*\|values [0-9]* bytes, structure [0-9]* bytes' | tr '\n' ' ')"
    done
done
for i in $(seq "$ROUNDS"); do
    for f in "${FILES[@]}"; do
        note "round $i $f:bake vdb_print_l $(secs vdb_print -l "$f.vdb") s"
        for b in "${BUILDS[@]}"; do
            note "round $i $f:bake $b $(secs "${BIN[$b]}/qbricks-bake" bake "$f.vdb" -o "/tmp/speed_goals_$b.qbk" --quiet) s"
        done
        for b in "${BUILDS[@]}"; do
            for k in 1 2 3; do
                note "round $i $f:open_checksum $b $("${BIN[$b]}/qbricks-view" render "${f}_$b.qbk" -o /tmp/speed_goals.png --width 16 --height 16 --json | json open_ms) ms"
                note "round $i $f:open_no_checksum $b $("${BIN[$b]}/qbricks-view" render "${f}_$b.qbk" -o /tmp/speed_goals.png --width 16 --height 16 --json --no-checksum | json open_ms) ms"
            done
        done
        for size in 1024 256; do
            repeat=$([[ $size = 256 ]] && echo 21 || echo 5)
            note "round $i $f:exact_$size vdb_render $(vdb_ms "$f" $size) ms"
            for b in "${BUILDS[@]}"; do
                note "round $i $f:exact_$size $b $("${BIN[$b]}/qbricks-view" render "${f}_$b.qbk" "${QB_CAM[@]}" --width $size --height $size --strategy exact --repeat $repeat --json -o /tmp/speed_goals.png | json ms) ms"
            done
        done
        for strategy in uniform paper bisect; do
            for b in "${BUILDS[@]}"; do
                note "round $i $f:${strategy}_1024 $b $("${BIN[$b]}/qbricks-view" render "${f}_$b.qbk" "${QB_CAM[@]}" --width 1024 --height 1024 --strategy $strategy --repeat 3 --json -o /tmp/speed_goals.png | json ms) ms"
            done
        done
    done
done
note "load after: $(uptime)"

# Medians per measurement and build.
python3 - "$LOG" <<'PY'
import collections, statistics, sys
runs = collections.defaultdict(list)
for line in open(sys.argv[1]):
    f = line.split()
    if f and f[0] == "round":
        runs[(f[2], f[3])].append(float(f[4]))
print("\nmedian (min, max) over rounds:")
for (what, build), v in sorted(runs.items()):
    print(f"  {what:30} {build:11} {statistics.median(v):9.2f} ({min(v):.2f}, {max(v):.2f})  n={len(v)}")
PY
