#!/usr/bin/env bash
# polymap's extraction beside CAPE (Proenca & Gao, IROS 2018), the fastest CPU plane
# extractor we know, in one run on the same frames: `polymap bench` (CPU path, one thread
# and every thread) and bench/cape/cape_bench.cpp (CAPE, one thread) over each sequence.
#
#   scripts/bench_cape.sh CAPE_CHECKOUT [FRAMES] [SEQ...]
#
# CAPE_CHECKOUT is a clone of github.com/pedropro/CAPE kept outside this repository (MIT;
# nothing of it is copied here); its sources are compiled with the harness into
# target/cape_bench. Needs g++, libopencv-dev and libeigen3-dev (installed if missing).
set -euo pipefail
cd "$(dirname "$0")/.."
cape=${1:?usage: scripts/bench_cape.sh CAPE_CHECKOUT [FRAMES] [SEQ...]}
frames=${2:-300}
shift $(($# < 2 ? $# : 2))
seqs=("$@")
[ ${#seqs[@]} -eq 0 ] && seqs=(mock_frames/straight_320 mock_frames/straight_640)
src="$cape/CAPE"
[ -f "$src/CAPE.cpp" ] || { echo "$cape: no CAPE/CAPE.cpp (a clone of pedropro/CAPE?)" >&2; exit 2; }

source scripts/need_debs.sh
need_debs g++ libopencv-dev libeigen3-dev pkg-config

mkdir -p target
if [ ! target/cape_bench -nt bench/cape/cape_bench.cpp ]; then
    echo "compiling CAPE from $src with bench/cape/cape_bench.cpp" >&2
    # -O3 -march=native: CAPE at its best on this CPU (its own CMakeLists says -O2).
    g++ -std=c++17 -O3 -march=native -w -I"$src" -I/usr/include/eigen3 $(pkg-config --cflags opencv4) \
        bench/cape/cape_bench.cpp "$src"/{CAPE,PlaneSeg,CylinderSeg,Histogram}.cpp \
        -o target/cape_bench $(pkg-config --libs opencv4)
fi
cargo build --release --quiet
cores=$(nproc)
out=$(mktemp -d)
for seq in "${seqs[@]}"; do
    name=$(basename "$seq")
    target/cape_bench "$seq" "$frames" > "$out/$name.cape.json"
    target/release/polymap bench "$seq" --backend cpu --frames "$frames" --threads 1 --json > "$out/$name.1.json"
    target/release/polymap bench "$seq" --backend cpu --frames "$frames" --threads "$cores" --json > "$out/$name.all.json"
done
python3 - "$out" "$cores" "${seqs[@]}" <<'PY'
import json, os, sys
out, cores, seqs = sys.argv[1], sys.argv[2], sys.argv[3:]
for seq in seqs:
    name = os.path.basename(seq)
    cape = json.load(open(f"{out}/{name}.cape.json"))
    runs = [(1, json.load(open(f"{out}/{name}.1.json"))), (cores, json.load(open(f"{out}/{name}.all.json")))]
    print(f"\n{seq}: {cape['width']}x{cape['height']}, {cape['frames']} frames a run, ms per frame (median / p99)")
    print(f"{'stage':>10} " + " ".join(f"{'polymap ' + str(t) + ' thr':>22}" for t, _ in runs))
    for stage in ["upload", "diffusion", "normals", "edges", "regions", "contours", "ransac", "polygons", "total"]:
        print(f"{stage:>10} " + " ".join(f"{r['stages_ms'][stage]['median']:>10.3f} / {r['stages_ms'][stage]['p99']:>9.3f}" for _, r in runs))
    print(f"{'CAPE 1 thr':>10} {cape['median_ms']:>10.3f} / {cape['p99_ms']:>9.3f}   ({cape['planes_per_frame']:.1f} planes a frame, {cape['patch']} px cells)")
    for t, r in runs:
        total = r["stages_ms"]["total"]
        print(f"polymap {t} thr / CAPE: {total['median'] / cape['median_ms']:.2f}x median, {total['p99'] / cape['p99_ms']:.2f}x p99")
PY
