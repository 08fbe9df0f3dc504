#!/bin/sh
# Seeds the `qbk_open` fuzz corpus with small real baked files (a few KB to ~200 KB each),
# so that the fuzzer starts from archives that validate and mutates real layouts rather
# than having to discover rkyv's structure from nothing.
#
# Usage (from the repository root, after `cargo build --release --workspace`):
#   sh fuzz/seed_qbk.sh [corpus dir, default fuzz/corpus/qbk_open]
set -eu
out=${1:-fuzz/corpus/qbk_open}
bake=${BAKE:-./target/release/qbricks-bake}
lab=${LAB:-./target/release/qbricks-lab}
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
mkdir -p "$out"

seed() { # name, synth arguments...
    name=$1
    shift
    "$lab" synth "$@" -o "$tmp/$name.vdb" >/dev/null
    "$bake" bake "$tmp/$name.vdb" -o "$out/$name.qbk" >/dev/null
}

seed wake8 wake --n0 8
seed wake12 wake --n0 12 --levels 2
seed wake10 wake --n0 10
seed wake_single8 wake-single --n0 8
seed lamb8 lamb-oseen --n0 8
seed lamb12 lamb-oseen --n0 12
seed abc8 abc --n0 8
seed burgers8 burgers --n0 8
ls -l "$out"
