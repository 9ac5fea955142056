#!/usr/bin/env bash
# Scores polymap on the SegComp ABW range images (Hoover et al. 1996) and fails below the
# figures README.md gives. The images may not be shipped with polymap (no licence; research
# use only), so the suite does not read them: CI runs this where ../shared/real/abw is, and
# anyone with the images can: bash scripts/abw.sh [DIR] (default ../shared/real/abw).
set -euo pipefail
cd "$(dirname "$0")/.."
dir=${1:-../shared/real/abw}
[ -d "$dir" ] || { echo "abw.sh: no ABW images at $dir" >&2; exit 2; }
bin=${POLYMAP_BIN:-target/debug/polymap}
[ -x "$bin" ] || cargo build --locked --bin polymap
# The suite's last build of the binary links librealsense2 (--features realsense): its path.
if [ -d target/pyenv ]; then
    source scripts/librealsense.sh target/pyenv
fi
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
"$bin" eval "$dir" --segmentation --json --config config/small-objects.toml > "$out/small.json"
"$bin" eval "$dir" --segmentation --json > "$out/stairs.json"
python3 - "$out" <<'PY'
import json, statistics, sys
out = sys.argv[1]
small = json.load(open(f"{out}/small.json"))
stairs = json.load(open(f"{out}/stairs.json"))
s, t = small["summary"], stairs["summary"]
angles = [a["error_deg"] for image in small["images"] for a in image["score"]["angle_errors"]]
print(f"small-objects config: {s['correct']:.2f} of {s['truth_faces']:.2f} faces correct an image "
      f"(fewest {s['correct_min']}), noise {s['noise']:.2f}; {len(angles)} angles, median error "
      f"{statistics.median(angles):.3f} deg")
print(f"stairs defaults: {t['correct']:.2f} correct an image")
# Images 0-14 hold 17.8 faces an image; measured 15.67 correct, 0.8 noise regions (the 1996
# paper's four segmenters: 9.7-13.4 of 15.2 over all 30); the stairs defaults find only
# the table and the back board.
failures = []
if abs(s["truth_faces"] - 17.8) >= 0.05: failures.append(f"truth faces {s['truth_faces']} (17.8 expected: wrong images?)")
if s["correct"] < 15.6: failures.append(f"correct {s['correct']:.2f} < 15.6")
if s["correct_min"] < 8: failures.append(f"fewest correct {s['correct_min']} < 8")
if s["noise"] > 1.2: failures.append(f"noise {s['noise']:.2f} > 1.2")
if t["correct"] > 3.0: failures.append(f"stairs defaults correct {t['correct']:.2f} > 3")
if len(angles) < 200 or statistics.median(angles) >= 0.5: failures.append("touching faces' angles: fewer than 200 or median >= 0.5 deg")
if failures:
    sys.exit("abw.sh: " + "; ".join(failures))
print("abw.sh: the ABW figures hold")
PY
