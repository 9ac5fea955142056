#!/usr/bin/env bash
# Makes librealsense2 2.56.5 available to `cargo build --features realsense` on a machine
# where it is not installed (CI, a laptop). On the robot, install Intel's librealsense2
# packages instead (README: "On the robot") and skip this.
#
# librealsense2 is not a Debian package, but the PyPI wheel pyrealsense2==2.56.5.9235,
# which matches realsense-sys 2.56.5, carries the whole library inside its extension
# module: that module exports the rs2_* C API. We install the wheel into the project's
# virtualenv (its Python API also writes the test bags), then turn a copy of the module
# into librealsense2.so.2.56 with a pkg-config file beside it.
#
# Usage: source scripts/librealsense.sh VENV
#   exports PKG_CONFIG_PATH and LD_LIBRARY_PATH so cargo finds and the tests load it.
# Sourced, so it leaves shell options to its caller (scripts/test.sh runs with set -euo
# pipefail, which stops at any failure here too).

venv="$1"
lib_dir="$PWD/target/librealsense"
wheel_version=2.56.5.9235

# Found without importing it: importing needs libusb, which is not this script's business.
module_dir=$("$venv/bin/python" -c \
    "import importlib.util as u; s = u.find_spec('pyrealsense2'); print(s.submodule_search_locations[0] if s else '')")
if [ -z "$module_dir" ]; then
    echo "installing pyrealsense2==$wheel_version into $venv"
    # numpy and pillow: scripts/make_bag.py reads the sequences' PNGs with them.
    "$venv/bin/pip" install -q --disable-pip-version-check "pyrealsense2==$wheel_version" numpy==2.4.6 pillow==13.0.0
    module_dir=$("$venv/bin/python" -c \
        "import importlib.util as u; print(u.find_spec('pyrealsense2').submodule_search_locations[0])")
fi

if [ ! -f "$lib_dir/realsense2.pc" ] || [ ! -f "$lib_dir/librealsense2.so.2.56" ]; then
    echo "making $lib_dir/librealsense2.so from the pyrealsense2 wheel"
    mkdir -p "$lib_dir"
    cp "$module_dir"/pyrealsense2.cpython-*.so "$lib_dir/librealsense2.so.2.56"
    # Two separate patchelf calls: done in one, the SONAME came out corrupted.
    patchelf --set-soname librealsense2.so.2.56 "$lib_dir/librealsense2.so.2.56"
    # The module leaves the Python C API symbols to its host interpreter; a Rust binary
    # has none, so the library must pull libpython in itself.
    patchelf --add-needed libpython3.11.so.1.0 "$lib_dir/librealsense2.so.2.56"
    ln -sf librealsense2.so.2.56 "$lib_dir/librealsense2.so"
    cat >"$lib_dir/realsense2.pc" <<EOF
libdir=$lib_dir
includedir=$lib_dir/include

Name: realsense2
Description: Intel RealSense SDK 2.0, from the pyrealsense2 $wheel_version wheel
Version: 2.56.5
Libs: -L\${libdir} -lrealsense2
Cflags: -I\${includedir}
EOF
fi

export PKG_CONFIG_PATH="$lib_dir${PKG_CONFIG_PATH:+:$PKG_CONFIG_PATH}"
export LD_LIBRARY_PATH="$lib_dir${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}"
