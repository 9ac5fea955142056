#!/usr/bin/env bash
# polymap for aarch64 (a Jetson Orin), built and checked on an x86-64 Debian/Ubuntu machine:
# cross-builds the release binary for aarch64-unknown-linux-gnu (no warning allowed), runs
# the CPU twin's stage tests under qemu-user at both of aarch64's vector levels, and holds
# `polymap eval` on the bundled mock sequences, run under qemu, to the x86-64 binary's.
# Installs what it needs first: the rustup target, Debian's cross C compiler and libc, and
# qemu-user. Speed cannot be measured here (qemu's timing is not a CPU's).
#
#   bash scripts/aarch64.sh [OUTDIR]     (default target/aarch64-check)
set -euo pipefail
cd "$(dirname "$0")/.."
out=${1:-target/aarch64-check}
mkdir -p "$out"
start=$(date +%s)
step() { echo "== $* ($(($(date +%s) - start)) s)"; }

source scripts/need_debs.sh
need_debs gcc-aarch64-linux-gnu libc6-dev-arm64-cross qemu-user python3
target=aarch64-unknown-linux-gnu
rustup target list --installed | grep -qx "$target" || rustup target add "$target"

# Cargo links with the cross gcc, the C in the dependencies (ring, zstd) compiles with it,
# and every target binary (the tests included) runs under qemu with the cross sysroot.
export CARGO_TARGET_AARCH64_UNKNOWN_LINUX_GNU_LINKER=aarch64-linux-gnu-gcc
export CC_aarch64_unknown_linux_gnu=aarch64-linux-gnu-gcc
export AR_aarch64_unknown_linux_gnu=aarch64-linux-gnu-ar
export CARGO_TARGET_AARCH64_UNKNOWN_LINUX_GNU_RUNNER=qemu-aarch64
export QEMU_LD_PREFIX=/usr/aarch64-linux-gnu
export CARGO_TARGET_AARCH64_UNKNOWN_LINUX_GNU_RUSTFLAGS="-D warnings"

step "release build for $target (default features: no RealSense)"
cargo build --release --locked --target "$target"
arm=target/$target/release/polymap
file "$arm" | tee "$out/binary.txt"

# The CPU twin's stages and the grid scans they share; the GPU twin needs a Vulkan
# device, which qemu has none of. NEON first (what an Orin runs), then the scalar oracles.
for simd in neon baseline; do
    step "stage tests under qemu-aarch64, POLYMAP_SIMD=$simd"
    POLYMAP_SIMD=$simd cargo test --release --locked --target "$target" --lib -- \
        extract:: grid:: --skip extract::gpu 2>&1 | tee "$out/lib_tests_$simd.txt" | grep -E '^test result'
    # The bench test runs the binary as a child, which qemu-user cannot start without the
    # kernel's binfmt_misc (absent in containers): the bench is run under qemu below.
    POLYMAP_SIMD=$simd cargo test --release --locked --target "$target" --test extract -- \
        --skip bench_runs_the_cpu_stages 2>&1 | tee "$out/extract_tests_$simd.txt" | grep -E '^test result'
    POLYMAP_SIMD=$simd qemu-aarch64 "$arm" bench mock_frames/straight_320 --backend cpu --frames 3 --json \
        >"$out/bench_$simd.json"
    grep -q "\"simd\": \"$simd\"" "$out/bench_$simd.json" || { echo "bench did not run at $simd"; exit 1; }
done

step "x86-64 release build"
cargo build --release --locked
x86=target/release/polymap

# The same arithmetic gives the same bits: at the baseline both targets run the scalar
# loops, at the widest level their f64 sums are added in other orders (AVX2's or
# AVX-512's four or eight lanes, NEON's two), which moves the last digits only.
for seq in straight_320 spiral_320 straight_640; do
    for level in baseline widest; do
        step "polymap eval mock_frames/$seq, $level vector level, x86-64 and aarch64"
        x86_simd=$level arm_simd=$level
        [ "$level" = widest ] && x86_simd=avx512 arm_simd=neon
        POLYMAP_SIMD=$x86_simd "$x86" eval "mock_frames/$seq" --backend cpu --json >"$out/eval_${seq}_${level}_x86_64.json"
        POLYMAP_SIMD=$arm_simd qemu-aarch64 "$arm" eval "mock_frames/$seq" --backend cpu --json >"$out/eval_${seq}_${level}_aarch64.json"
    done
done

step "aarch64 against x86-64"
python3 - "$out" <<'EOF'
import json, sys
out = sys.argv[1]

def leaves(v, path=""):
    if isinstance(v, dict):
        for k, x in v.items():
            yield from leaves(x, f"{path}.{k}")
    elif isinstance(v, list):
        for i, x in enumerate(v):
            yield from leaves(x, f"{path}[{i}]")
    else:
        yield path, v

def compare(a_file, b_file):
    """(values, [(difference, relative difference, path)] of the numbers that differ, the
    paths where anything else differs)."""
    la, lb = (list(leaves(json.load(open(f)))) for f in (a_file, b_file))
    if [p for p, _ in la] != [p for p, _ in lb]:
        return len(la), [], ["shape (a tread found on one only)"]
    number = lambda v: isinstance(v, (int, float)) and not isinstance(v, bool)
    diffs = [(abs(x - y), abs(x - y) / max(abs(x), abs(y)), p) for (p, x), (_, y) in zip(la, lb)
             if x != y and number(x) and number(y)]
    return len(la), diffs, [p for (p, x), (_, y) in zip(la, lb) if x != y and not (number(x) and number(y))]

# The bounds: at the baseline the same arithmetic, but for glibc's hypot, which differs in
# its last bit between the two targets (a plane's halves' bend goes through it); at the
# widest levels the f64 sums' order.
bounds = {"baseline": ("relative", 1e-15), "widest": ("absolute", 1e-6)}
failed = False
for seq in ["straight_320", "spiral_320", "straight_640"]:
    for level in ["baseline", "widest"]:
        n, diffs, other = compare(*(f"{out}/eval_{seq}_{level}_{arch}.json" for arch in ["x86_64", "aarch64"]))
        kind, bound = bounds[level]
        worst = max(diffs, default=(0.0, 0.0, "-"))
        size = worst[1] if kind == "relative" else worst[0]
        fields = sorted({p.rsplit(".", 1)[-1] for _, _, p in diffs})
        print(f"{seq:13} {level:8}: {n} values, {len(diffs)} differ (in {', '.join(fields) or 'none'}), "
              f"largest {worst[0]:.3g} ({worst[1]:.3g} relative) at {worst[2]}"
              + (f"; differ otherwise at {other[:3]}" if other else ""))
        if other or size > bound:
            print(f"  over the bound: {kind} {bound:g}")
            failed = True
    # For scale: the same binary's widest level against its baseline.
    n, diffs, _ = compare(f"{out}/eval_{seq}_baseline_x86_64.json", f"{out}/eval_{seq}_widest_x86_64.json")
    print(f"{seq:13} x86-64 widest vs its baseline: {len(diffs)} differ, largest {max(diffs, default=(0.0,))[0]:.3g}")
print("aarch64 outputs: " + ("DIFFER" if failed else
      "the same bits at the baseline but glibc's hypot (1e-15 relative), within 1e-6 at the widest levels"))
sys.exit(1 if failed else 0)
EOF
step "done"
