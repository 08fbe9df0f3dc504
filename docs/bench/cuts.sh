#!/usr/bin/env bash
# Frame time of the cutting features (clip plane, slice, two iso-surfaces) against the plain
# frame, in interleaved rounds so every configuration sees the same load; prints each
# round's times and the medians of the per-round ratios to the plain frame.
#
#   docs/bench/cuts.sh FILE.qbk [ROUNDS] [THREADS]
#
# FILE.qbk: e.g. the n0-128 wake (qbricks-lab synth wake -o w.vdb --n0 128 --levels 3;
# qbricks-bake bake w.vdb -o w.qbk). Uses target/release/qbricks-view (cargo build --release).
set -euo pipefail
file=${1:?usage: docs/bench/cuts.sh FILE.qbk [ROUNDS] [THREADS]}
rounds=${2:-5}
threads=${3:-2}
view=${QBRICKS_VIEW:-target/release/qbricks-view}
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
cam=(--eye 3.5,-4.5,2 --look-at 2.3,0,0 --up 0,0,1 --fov 30 --width 1024 --height 1024
     --threads "$threads" --repeat 3 --json --overlays none)
names=(plain clip slice two_isos all)
args_of() {
    case $1 in
        plain) echo "--iso 0.05" ;;
        clip) echo "--iso 0.05 --clip y<0" ;;
        slice) echo "--iso 0.05 --slice 0,0,0:0,0,1 --slice-opacity 0.6" ;;
        two_isos) echo "--iso 0.02,0.05 --iso-opacity 0.3,1" ;;
        all) echo "--iso 0.02,0.05 --iso-opacity 0.3,1 --clip y<0 --slice 0,0,0:0,0,1 --slice-opacity 0.6" ;;
    esac
}
for r in $(seq 1 "$rounds"); do
    for k in "${names[@]}"; do
        # shellcheck disable=SC2046
        ms=$("$view" render "$file" -o "$out/$k.png" "${cam[@]}" $(args_of "$k") |
            python3 -c "import json,sys; print(json.load(sys.stdin)['ms'])")
        echo "$r $k $ms"
    done
done | tee "$out/times.txt"
python3 - "$out/times.txt" <<'PY'
import collections, statistics, sys
d = collections.defaultdict(dict)
for line in open(sys.argv[1]):
    r, k, ms = line.split()
    d[r][k] = float(ms)
for k in ["plain", "clip", "slice", "two_isos", "all"]:
    ms = statistics.median(d[r][k] for r in d)
    ratio = statistics.median(d[r][k] / d[r]["plain"] for r in d)
    print(f"{k:9s} median {ms:7.0f} ms   median ratio to plain {ratio:.2f}")
PY
