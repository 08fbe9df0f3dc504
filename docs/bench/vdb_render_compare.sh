#!/usr/bin/env bash
# qbricks against OpenVDB's vdb_render on the same data and camera (BENCHMARKS.md,
# "OpenVDB vdb_render comparison"). Run from the repository root after
# `cargo build --release --workspace --examples`; needs vdb_render and vdb_tool
# (Debian: libopenvdb-tools).
#
#   docs/bench/vdb_render_compare.sh [WORKDIR=/tmp/vdb_compare] [REPEAT=3] [THREADS=2]
#
# FILE=independent runs it on issue 33's independent layout
# (docs/bench/layouts/independent.json) instead of the n0-128 wake (FILE=wake128, the
# default).
#
# 1. synth + bake the file (skipped when WORKDIR already holds them);
# 2. resample the bake's Q onto one uniform grid at the finest cell width
#    (examples/qbk_to_vdb.rs): q.vdb (−Q) and fog.vdb (a 0→1 ramp of Q over the band);
# 3. vdb_tool -iso2ls: the Q = ISO surface as a narrow-band level set (timed on its own);
# 4. back to back, REPEAT times: qbricks iso (exact), vdb_render on the level set,
#    qbricks dvr (default, and uniform step 1 pre-integrated), vdb_render on the fog volume.
# Prints one line per run (render time only: no file reading, no PNG writing) and the load
# average before and after. Images: WORKDIR/{qb_iso,vdb_ls,qb_dvr,qb_dvr_pre,vdb_fog}.png.
set -euo pipefail

WORK=${1:-/tmp/vdb_compare}
REPEAT=${2:-3}
THREADS=${3:-2}
ISO=0.05
ROOT=$(pwd)
FILE=${FILE:-wake128}
BAKE="$ROOT/target/release/qbricks-bake"
VIEW="$ROOT/target/release/qbricks-view"
LAB="$ROOT/target/release/qbricks-lab"
EXPORT="$ROOT/target/release/examples/qbk_to_vdb"
for exe in "$BAKE" "$VIEW" "$LAB" "$EXPORT"; do
    [[ -x $exe ]] || { echo "missing $exe: cargo build --release --workspace --examples" >&2; exit 2; }
done
for tool in vdb_render vdb_tool; do
    command -v $tool >/dev/null || { echo "missing $tool: apt-get install libopenvdb-tools" >&2; exit 2; }
done
mkdir -p "$WORK"
cd "$WORK"

# The camera of BENCHMARKS.md, as qbricks flags and as vdb_render flags. vdb_render's
# -fov is horizontal, qbricks' vertical: equal for a square image. Its -light needs the
# colour too (with only a direction the light is black).
EYE=3.5,-4.5,2; LOOK=2.3,0,0; UP=0,0,1; FOV=30; RES=1024
QB_CAM=(--eye $EYE --look-at $LOOK --up $UP --fov $FOV --width $RES --height $RES --iso $ISO)
VDB_CAM=(-res ${RES}x${RES} -translate $EYE -lookat $LOOK -up $UP -fov $FOV -cpus $THREADS)

if [[ ! -f $FILE.qbk ]]; then
    case $FILE in
        wake128) "$LAB" synth wake -o wake128.vdb --n0 128 --levels 3 ;;
        independent) "$LAB" synth wake -o independent.vdb --boxes "$ROOT/docs/bench/layouts/independent.json" ;;
        *) echo "FILE=$FILE: expected wake128 or independent" >&2; exit 2 ;;
    esac
    "$BAKE" bake "$FILE.vdb" -o "$FILE.qbk"
fi
echo "load before: $(uptime)"
t0=$(date +%s.%N)
"$EXPORT" "$FILE.qbk" q.vdb fog.vdb --iso $ISO
echo "resample to uniform grid: $(echo "$(date +%s.%N) - $t0" | bc) s"
t0=$(date +%s.%N)
vdb_tool -quiet -read q.vdb -iso2ls iso=-$ISO width=3 -write ls.vdb
echo "vdb_tool -iso2ls (read, convert, write): $(echo "$(date +%s.%N) - $t0" | bc) s"

qb_ms() { "$VIEW" render "$FILE.qbk" "${QB_CAM[@]}" --threads "$THREADS" --json "$@" |
    grep -o '"ms":[0-9.]*' | cut -d: -f2 | xargs printf '%.0f'; }
vdb_ms() { vdb_render "$@" "${VDB_CAM[@]}" -v 2>&1 |
    awk '/ray-tracing/ {r=1} r && /completed in/ {print $(NF-1) * 1000; exit}'; }

for i in $(seq "$REPEAT"); do
    echo "run $i: qbricks iso exact            $(qb_ms --mode iso -o qb_iso.png) ms"
    echo "run $i: vdb_render level set         $(vdb_ms ls.vdb vdb_ls.png -shader diffuse) ms"
    echo "run $i: qbricks dvr default          $(qb_ms --mode dvr -o qb_dvr.png) ms"
    echo "run $i: qbricks dvr uniform 1 +pre   $(qb_ms --mode dvr --strategy uniform --step 1 --preintegrated -o qb_dvr_pre.png) ms"
    echo "run $i: vdb_render fog step 1        $(vdb_ms fog.vdb vdb_fog.png -light 0.2,-0.8,0.6,1,1,1) ms"
    echo "run $i: vdb_render fog step 0.5      $(vdb_ms fog.vdb vdb_fog_05.png -light 0.2,-0.8,0.6,1,1,1 -step 0.5) ms"
done
echo "load after: $(uptime)"

# Side by side (docs/bench/vdb_compare.png), if ImageMagick is there.
if command -v montage >/dev/null; then
    for f in qb_iso vdb_ls qb_dvr_pre vdb_fog; do
        convert $f.png -crop 1024x480+0+270 +repage -resize 512x $f.crop.png
    done
    font=(); [[ -f /usr/share/fonts/truetype/dejavu/DejaVuSans.ttf ]] &&
        font=(-font /usr/share/fonts/truetype/dejavu/DejaVuSans.ttf)
    montage "${font[@]}" -label 'qbricks iso (exact)' qb_iso.crop.png \
        -label 'vdb_render level set' vdb_ls.crop.png \
        -label 'qbricks dvr (uniform 1, pre-integrated)' qb_dvr_pre.crop.png \
        -label 'vdb_render fog (step 1)' vdb_fog.crop.png \
        -tile 2x2 -geometry +3+3 -background '#202020' -fill white -pointsize 14 vdb_compare.png
fi
