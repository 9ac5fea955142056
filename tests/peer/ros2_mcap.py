#!/usr/bin/env python3
"""ROS 2 bags in MCAP for tests/logs.rs, written with rosbags (PyPI), sharing no code with polymap.

- `write-sequence OUT_DIR SEQ`: a polymap sequence as a ROS 2 robot records it, a rosbag2
  directory with MCAP storage: the depth frames as realsense-ros (ROS 2) publishes them
  under its default names, as 32FC1 in metres (REP 118's other depth encoding), with their
  camera_info, and each frame's pose as nav_msgs/Odometry on /odometry.
- `write-wrong-type OUT_DIR`: a rosbag2 directory whose depth topic carries a
  sensor_msgs/CompressedImage.
"""

import pathlib
import sys

import numpy as np
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
import ros2_msgs as msgs  # noqa: E402
from polymap_sequence import camera_toml, read_png16, read_poses  # noqa: E402

DEPTH = "/camera/camera/depth/image_rect_raw"
INFO = "/camera/camera/depth/camera_info"
ODOMETRY = "/odometry"
FRAME = "camera_depth_optical_frame"

store = get_typestore(Stores.ROS2_HUMBLE)
T = store.types


def write(w, conn, stamp_ns, msg):
    w.write(conn, stamp_ns, store.serialize_cdr(msg, msg.__msgtype__))


def write_sequence(out, seq):
    seq = pathlib.Path(seq)
    cam = camera_toml(seq)
    with Writer(out, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        depth = w.add_connection(DEPTH, "sensor_msgs/msg/Image", typestore=store)
        info_c = w.add_connection(INFO, "sensor_msgs/msg/CameraInfo", typestore=store)
        odom_c = w.add_connection(ODOMETRY, "nav_msgs/msg/Odometry", typestore=store)
        for k, (stamp_ns, p, q) in enumerate(read_poses(seq)):
            odom = msgs.odometry(T, stamp_ns, p, q)
            write(w, odom_c, stamp_ns, odom)
            width, height, samples = read_png16(seq / "depth" / f"{k:06d}.png")
            units = np.frombuffer(bytes(samples), dtype=">u2").astype(np.float64)
            metres = (units * cam["depth_scale"]).astype("<f4")
            info = msgs.camera_info(T, stamp_ns, FRAME, cam, width, height)
            write(w, info_c, stamp_ns, info)
            image = msgs.image(T, stamp_ns, FRAME, width, height, "32FC1", 4 * width, metres.tobytes())
            write(w, depth, stamp_ns, image)


def write_wrong_type(out):
    with Writer(out, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        c = w.add_connection(DEPTH, "sensor_msgs/msg/CompressedImage", typestore=store)
        for k in range(3):
            m = T["sensor_msgs/msg/CompressedImage"](header=msgs.header(T, k, "camera"), format="png",
                                                      data=np.zeros(4, dtype=np.uint8))
            write(w, c, k, m)


if __name__ == "__main__":
    {"write-sequence": write_sequence, "write-wrong-type": write_wrong_type}[sys.argv[1]](*sys.argv[2:])
