#!/usr/bin/env bash
# The GPU path on a real GPU, in one go: the GPU-vs-CPU tests, `polymap bench --backend
# gpu` per stage (GPU timestamps) at 320x240 and 640x480, the CPU path on the same
# machine for comparison, and `polymap eval --backend gpu` on the mock sequences.
#
#   scripts/bench_gpu.sh POLYMAP GPU_TESTS OUTDIR [FRAMES [BASELINE]]
#
# POLYMAP is a release build of polymap and GPU_TESTS the test binary of tests/gpu.rs
# (`cargo test --release --test gpu --no-run` names it); both are built elsewhere and
# carried to the GPU machine, which needs only a Vulkan loader and driver. BASELINE, an
# older build, is benched on the GPU beside it in the same run. Everything lands in
# OUTDIR; the last lines printed are the summary.
set -uo pipefail
cd "$(dirname "$0")/.."
polymap=${1:?usage: scripts/bench_gpu.sh POLYMAP GPU_TESTS OUTDIR [FRAMES]}
tests=${2:?}
out=${3:?}
frames=${4:-1000}
baseline=${5:-}
mkdir -p "$out"

command -v nvidia-smi >/dev/null && nvidia-smi --query-gpu=name,driver_version,clocks.sm,clocks.mem,temperature.gpu,utilization.gpu \
    --format=csv 2>&1 | tee "$out/gpu.txt"
nproc | sed 's/^/cores: /' | tee -a "$out/gpu.txt"
grep -m1 'model name' /proc/cpuinfo | tee -a "$out/gpu.txt"

# The tests first: figures from a GPU that gives wrong answers would be worth nothing.
CI=true timeout 240 "$tests" --test-threads 1 --nocapture >"$out/gpu_tests.txt" 2>&1
echo "gpu tests: rc $? ($(grep -E '^test result' "$out/gpu_tests.txt"))"

# A GPU idles at a low clock: a warm-up run first, so that the timed runs see the clock
# the work brings it to. With a baseline the runs go new, old, old, new.
gpu_bench() { # BINARY SEQ NAME
    timeout 120 "$1" bench "mock_frames/$2" --backend gpu --frames "$frames" --json \
        >"$out/$3_$2.json" 2>"$out/$3_$2.log" || echo "bench gpu $3 $2 failed: $(tail -3 "$out/$3_$2.log")"
}
timeout 120 "$polymap" bench mock_frames/straight_640 --backend gpu --frames 300 >/dev/null 2>&1
for seq in straight_640 straight_320; do
    gpu_bench "$polymap" "$seq" gpu
    if [ -n "$baseline" ]; then
        gpu_bench "$baseline" "$seq" gpubase
        gpu_bench "$baseline" "$seq" gpubase2
        gpu_bench "$polymap" "$seq" gpu2
    fi
    for t in 1 "$(nproc)"; do
        timeout 120 "$polymap" bench "mock_frames/$seq" --backend cpu --frames 300 --threads "$t" --json \
            >"$out/cpu${t}_$seq.json" 2>/dev/null || echo "bench cpu $t $seq failed"
    done
done
for seq in straight_320 spiral_320 straight_640; do
    timeout 120 "$polymap" eval "mock_frames/$seq" --backend gpu --json >"$out/eval_$seq.json" 2>"$out/eval_$seq.log" \
        || echo "eval gpu $seq failed: $(tail -3 "$out/eval_$seq.log")"
done
grep -h -m1 'extraction on the GPU' "$out"/gpu_*.log | head -1

# Summary: median and p99 of every stage, each bench side by side.
python3 - "$out" <<'EOF'
import json, os, sys, pathlib
out = pathlib.Path(sys.argv[1])
for seq in ("straight_640", "straight_320"):
    runs = {}
    for name in (f"gpu_{seq}", f"gpu2_{seq}", f"gpubase_{seq}", f"gpubase2_{seq}", f"cpu1_{seq}", f"cpu{os.cpu_count()}_{seq}"):
        if not (out / f"{name}.json").exists():
            continue
        try:
            runs[name] = json.loads((out / f"{name}.json").read_text())
        except Exception as e:
            print(name, "unreadable:", e)
    if not runs:
        continue
    order = ["upload", "diffusion", "normals", "edges", "regions", "readback", "contours", "ransac", "polygons", "total", "gpu_busy"]
    print(f"\n{seq} ({next(iter(runs.values()))['width']}x{next(iter(runs.values()))['height']}): ms median / p99")
    for n, r in runs.items():
        print(f"  {n}: {r['device']}, {r['frames']} frames, {r['fps']:.0f} fps end to end")
    print(f"{'stage':>10} " + "  ".join(f"{n.removesuffix('_' + seq):>19}" for n in runs))
    for st in order:
        # An older build's JSON may lack a stage (gpu_busy came in round 34).
        cells = [f"{r['stages_ms'][st]['median']:8.3f} / {r['stages_ms'][st]['p99']:8.3f}" if st in r['stages_ms']
                 else f"{'-':>19}" for r in runs.values()]
        print(f"{st:>10} " + "  ".join(cells))
EOF
