#!/bin/sh
# Seeds the `sequence_state` fuzz corpus with real inputs of `qbricks-view render` on a
# frame sequence: the manifest `qbricks-bake bake 'in_####.vdb' -o 'out_####.qbk'` writes
# (with a failed and a missing frame), view states `qbricks-view render --save-state`
# writes, and command-line flags, each seed `MANIFEST 0xFF STATE 0xFF FLAGS` as the target
# reads it (an empty part: no manifest, no --state, no flags). About 3 KB each.
#
# Usage (from the repository root, after `cargo build --release --workspace`):
#   sh fuzz/seed_sequence_state.sh [corpus dir, default fuzz/corpus/sequence_state]
set -eu
out=${1:-fuzz/corpus/sequence_state}
bake=${BAKE:-./target/release/qbricks-bake}
view=${VIEW:-./target/release/qbricks-view}
lab=${LAB:-./target/release/qbricks-lab}
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
mkdir -p "$out"

# Frames 1 and 4 bake, 2 is not a VDB file (failed), 3 is missing.
"$lab" synth ring-plume --n0 8 --frames 4 -o "$tmp/in_####.vdb" >/dev/null
rm "$tmp/in_0003.vdb"
echo 'not a VDB file' >"$tmp/in_0002.vdb"
"$bake" bake "$tmp/in_####.vdb" -o "$tmp/out_####.qbk" >/dev/null 2>&1 || true
test -s "$tmp/out_sequence.json"
# The manifest names its files as given; the seeds hold them relative.
sed "s|$tmp/||g" "$tmp/out_sequence.json" >"$tmp/manifest.json"
: >"$tmp/none"

state() { # name, render flags...
    name=$1
    shift
    "$view" render "$tmp/out_####.qbk" -o "$tmp/png_####.png" --width 8 --height 6 \
        --save-state "$tmp/$name.json" "$@" 2>/dev/null
    sed "s|$tmp/||g" "$tmp/$name.json" >"$tmp/$name.state"
}
state plain
state dvr --mode dvr --shadows --mesh data/sphere.obj@0.5,0.5,0.5,0.2
state ortho --ortho 1.5 --strategy bisect --iso-field speed --no-preintegrated
# The bundled sample's view: a camera looking past the sequence's box.
"$view" render data/wake_small.qbk -o "$tmp/x.png" --width 8 --height 6 \
    --save-state "$tmp/wake.state" 2>/dev/null

n=0
seed() { # manifest file, state file, flags
    n=$((n + 1))
    {
        cat "$1"
        printf '\377'
        cat "$2"
        printf '\377%s' "$3"
    } >"$out/seed_$n"
}
for m in "$tmp/manifest.json" "$tmp/none"; do
    for s in none plain dvr ortho wake; do
        st="$tmp/$s.state"
        [ "$s" = none ] && st="$tmp/none"
        for f in "" "--mode dvr" "--mode dvr --no-preintegrated --strategy bisect" \
            "--strategy uniform --shadows --mesh m.obj@0.5,0.5,0.5,0.3" \
            "--ortho 2 --eye 3,0.5,0.5 --look-at 0.5,0.5,0.5 --up 0,0,1" \
            "--iso-field speed --colour-field q" "--frames 1..3 --aov depth" \
            "--aov normal --pixel 3,2" "--spp 2 --iso 0.01 --fov 60 --aov level" \
            "--no-checksum --frames 3.. --aov value"; do
            seed "$m" "$st" "$f"
        done
    done
done
echo "$n seeds in $out"
