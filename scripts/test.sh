#!/usr/bin/env bash
# Runs polymap's whole test suite on a fresh Debian/Ubuntu machine with Rust.
# Installs what the tests need first: Mesa's software Vulkan (lavapipe) so the wgpu
# pipeline runs where there is no GPU.
set -euo pipefail
cd "$(dirname "$0")/.."

need_debs() {
    local missing=()
    for p in "$@"; do dpkg -s "$p" >/dev/null 2>&1 || missing+=("$p"); done
    [ ${#missing[@]} -eq 0 ] && return
    echo "installing ${missing[*]}"
    local sudo=""; [ "$(id -u)" -ne 0 ] && sudo="sudo"
    $sudo apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
}
need_debs mesa-vulkan-drivers libvulkan1

# All targets: library, binary, integration tests, examples, and each benchmark run once.
cargo test --locked --all-targets
