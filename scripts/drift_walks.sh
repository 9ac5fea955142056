#!/usr/bin/env bash
# polymap's own walks with the odometry drifting in x, y, z and yaw, mapped with exact and
# drifting poses, scored per tread (docs/figures.md "Drift in four degrees of freedom").
# Usage: scripts/drift_walks.sh [OUT_DIR] [SEEDS...]   (default: target/drift-walks, seeds 1 2 3)
# Env: POLYMAP (the binary; default: a release build), POLYMAP_CONFIG (a config for replay),
#      FRAMES (per walk, default 60), WIDTH (default 320).
set -euo pipefail
cd "$(dirname "$0")/.."
out=${1:-target/drift-walks}
shift || true
seeds=${*:-1 2 3}
frames=${FRAMES:-60}
width=${WIDTH:-320}
if [ -z "${POLYMAP:-}" ]; then
    cargo build --locked --release --bin polymap >&2
    POLYMAP=target/release/polymap
fi
config=()
[ -n "${POLYMAP_CONFIG:-}" ] && config=(--config "$POLYMAP_CONFIG")
mkdir -p "$out"
# Each walk's length seen from above, m: the drifts are per cent of it, spread over its frames.
length() { awk 'NR > 1 && !/^#/ { if (n++) d += sqrt(($2 - x) ^ 2 + ($3 - y) ^ 2); x = $2; y = $3 } END { print d }' "$1/poses.txt"; }
printf '%-9s %-4s %4s %-10s %7s %7s %9s %9s %9s %9s\n' scene walk seed drift iou_mean iou_min height_mm drift_xy_mm drift_yaw_deg steps
for scene in straight spiral; do
    for walk in up down; do
        for seed in $seeds; do
            base="$out/$scene-$walk-$seed"
            "$POLYMAP" synth "$base-exact" --scene "$scene" --walk "$walk" --frames "$frames" --width "$width" --seed "$seed" >/dev/null
            d=$(length "$base-exact")
            n=$((frames - 1))
            # 1 % (3 %) of the walk horizontally, at 45 degrees; 0.5 (2) degrees of yaw over it;
            # the height drifting 0.5 mm a frame; the jump: 10 cm and 1 degree half way.
            per() { awk -v d="$d" -v n="$n" -v p="$1" 'BEGIN { printf "%.6f", d * p / 100 / n / sqrt(2) * 1000 }'; }
            yaw() { awk -v n="$n" -v t="$1" 'BEGIN { printf "%.6f", t / n }'; }
            declare -A args=(
                [realistic]="--drift 0.5 --drift-xy $(per 1) $(per 1) --drift-yaw $(yaw 0.5)"
                [strong]="--drift 0.5 --drift-xy $(per 3) $(per 3) --drift-yaw $(yaw 2)"
                [jump]="--drift 0.5 --drift-xy $(per 1) $(per 1) --drift-yaw $(yaw 0.5) --jump $((frames / 2)) 70.7 70.7 0 1"
            )
            for kind in exact realistic strong jump; do
                seq="$base-$kind"
                # shellcheck disable=SC2086
                [ "$kind" = exact ] || "$POLYMAP" synth "$seq" --scene "$scene" --walk "$walk" --frames "$frames" --width "$width" --seed "$seed" ${args[$kind]} >/dev/null
                "$POLYMAP" replay "$seq" "${config[@]}" --out "$seq.json" --drift-trace "$seq.drift" >/dev/null 2>&1
                "$POLYMAP" eval "$seq" --map "$seq.json" --json >"$seq.eval.json"
                python3 - "$seq.eval.json" "$scene" "$walk" "$seed" "$kind" "$seq.drift.csv" <<'PY'
import json, sys
e = json.load(open(sys.argv[1]))["summary"]
steps = sum(1 for l in open(sys.argv[6]) if l.split(",")[-1].strip() == "1")
print(f"{sys.argv[2]:<9} {sys.argv[3]:<4} {sys.argv[4]:>4} {sys.argv[5]:<10} {e['iou_mean']:7.3f} {e['iou_min']:7.3f} "
      f"{e['height_error_max_mm']:9.2f} {e['drift_error_xy_mm']:9.2f} {e['drift_error_yaw_deg']:9.3f} {steps:9d}")
PY
            done
        done
    done
done
