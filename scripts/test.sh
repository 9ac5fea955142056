#!/usr/bin/env bash
# Runs polymap's whole test suite on a fresh Debian/Ubuntu machine with Rust.
# Installs what the tests need first: Mesa's software Vulkan (lavapipe) so the wgpu
# pipeline runs where there is no GPU; a Python virtualenv for the Python client tests;
# librealsense2 2.54 (the system's, or from the pyrealsense2 wheel), so the `realsense`
# feature builds, links and plays bags here (scripts/librealsense.sh); and ROS 1 from the
# distribution's archive (Debian 12's ros_comm, Noetic's). Works with whatever python3 the
# machine has.
set -euo pipefail
cd "$(dirname "$0")/.."

source scripts/need_debs.sh
need_debs mesa-vulkan-drivers libvulkan1 python3-venv pkg-config patchelf binutils libusb-1.0-0 libudev1
# A real ROS 1 for tests/ros1.rs: Debian's ros_comm (Noetic's 1.15), rosbag (its record and
# play are roscpp programs), genmsg/genpy, catkin (which builds polymap_msgs as on a robot)
# and the common messages, with Debian's python3
# (rospy is not on PyPI).
need_debs ros-core python3-rospy python3-rostopic python3-rosservice python3-rosnode python3-genmsg python3-genpy \
    ros-std-msgs ros-geometry-msgs ros-nav-msgs ros-sensor-msgs ros-visualization-msgs ros-tf2-msgs \
    python3-std-msgs python3-geometry-msgs python3-nav-msgs python3-sensor-msgs python3-visualization-msgs \
    python3-tf2-msgs python3-rosbag catkin ros-message-generation ros-message-runtime cmake g++

# The Python peers: eclipse-zenoh and rosbags from PyPI in a virtualenv of our own, and
# zenoh-ros2-sdk (robotis-git/zenoh_ros2_sdk), an rmw_zenoh client that shares no code with
# polymap, as the independent ROS 2 node of tests/ros2_peer.rs.
# Every package pinned in tests/peer/requirements.txt; the venv is made again when it changes.
venv=target/pyenv
requirements=tests/peer/requirements.txt
if ! cmp -s "$requirements" "$venv/requirements.txt"; then
    echo "making $venv (eclipse-zenoh, rosbags, zenoh-ros2-sdk, as $requirements pins them)"
    rm -rf "$venv"
    # Debian's own python (python3-venv above), not whatever python3 is first on PATH.
    py=/usr/bin/python3; [ -x "$py" ] || py=python3
    "$py" -m venv "$venv"
    "$venv/bin/pip" install -q --disable-pip-version-check -r "$requirements"
    cp "$requirements" "$venv/requirements.txt"
fi
export POLYMAP_PYTHON="$PWD/$venv/bin/python"

# librealsense2 for --features realsense: sets PKG_CONFIG_PATH and LD_LIBRARY_PATH.
source scripts/librealsense.sh "$venv"

# The Quick start's build, default features (no `realsense`), as `cargo run --release --
# demo` makes it; in debug, which reuses the suite's dependencies.
cargo build --locked --bin polymap
# The cargo-fuzz targets (fuzz/, a member of this workspace): built, so they never fall out
# of step with polymap::fuzz; cargo-fuzz runs them for long (docs/testing.md).
cargo build --locked -p polymap-fuzz
# The examples as programs: tests/readme_clients.rs runs the Rust planner client as the
# README does (`cargo test --all-targets` builds examples only as test harnesses).
cargo build --locked --examples --features realsense
# All targets (library, binary, integration tests, examples, each benchmark run once),
# with the RealSense drivers compiled, linked and tested against recorded bags.
cargo test --locked --all-targets --features realsense
# The CPU twin's stage tests again at each narrower vector width (POLYMAP_SIMD caps what
# the loops use): a CI machine with AVX-512 would otherwise test its widest path only.
for simd in avx2 baseline; do
    POLYMAP_SIMD=$simd cargo test --locked --features realsense --lib extract::
done
