#!/usr/bin/env python3
"""The depth camera of tests/ros2_peer.rs's ROS depth source test: a node on rmw_zenoh
(examples/python/rmw_zenoh.py, sharing no code with polymap) that publishes a sequence's
depth frames as realsense-ros publishes the L515's (sensor_msgs/Image 16UC1 on
/l515/depth/image_rect_raw, in the sequence's own unit, with its camera_info), and each
frame's pose on /odometry as VINS would, then two images polymap must refuse (an RGB image,
a size its camera_info does not have). It listens to polymap's frame polygons and map
updates, and prints, per frame polymap mapped: the frame's index, stamp, the map's drift
then, and the polygons' outlines (the JSON tests/ros1.rs's rospy camera prints).
"""

import argparse
import json
import pathlib
import sys
import threading
import time

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[2] / "examples" / "python"))
sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))

import ros2_msgs as msgs  # noqa: E402
from rmw_zenoh import Peer  # noqa: E402
from polymap_sequence import camera_toml, read_png16, read_poses  # noqa: E402

FRAME = "l515_depth_optical_frame"


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--connect", required=True)
    ap.add_argument("--namespace", required=True, help="polymap's node namespace and name, e.g. /polymap/leju")
    ap.add_argument("--sequence", required=True, type=pathlib.Path)
    ap.add_argument("--frames", type=int, default=24)
    ap.add_argument("--rate", type=float, default=3.0)
    args = ap.parse_args()
    cam = camera_toml(args.sequence)
    poses = read_poses(args.sequence)

    with Peer(args.connect, node="l515_depth") as peer:
        m = peer.store.types
        lock = threading.Lock()
        polygons, drift = {}, {}

        def ns(stamp):
            return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)

        def on_polygons(msg, _):
            with lock:
                polygons[ns(msg.header.stamp)] = [[[float(p.x), float(p.y), float(p.z)] for p in poly.boundary]
                                                  for poly in msg.polygons]

        def on_update(msg, _):
            with lock:
                drift[ns(msg.header.stamp)] = float(msg.drift_z)

        peer.subscribe(f"{args.namespace}/frame_polygons", "polymap_msgs/msg/FramePolygons", on_polygons)
        peer.subscribe(f"{args.namespace}/map_updates", "polymap_msgs/msg/MapUpdate", on_update)
        put_image = peer.publisher("/l515/depth/image_rect_raw", "sensor_msgs/msg/Image")
        put_info = peer.publisher("/l515/depth/camera_info", "sensor_msgs/msg/CameraInfo")
        put_odometry = peer.publisher("/odometry", "nav_msgs/msg/Odometry", qos="::,100:,:,:,,")
        # Ready once polymap's subscriptions and publishers are in the graph.
        for kind, name in [("MS", "/l515/depth/image_rect_raw"), ("MS", "/l515/depth/camera_info"),
                           ("MS", "/odometry"), ("MP", f"{args.namespace}/frame_polygons"),
                           ("MP", f"{args.namespace}/map_updates")]:
            peer.wait_for(kind, name)

        def info(stamp, width, height):
            return msgs.camera_info(m, stamp, FRAME, cam, width, height)

        def image(stamp, width, height, encoding, step, data):
            return msgs.image(m, stamp, FRAME, width, height, encoding, step, data)

        sent = []
        step = max(1, len(poses) // args.frames)
        for k in range(0, min(len(poses), step * args.frames), step):
            width, height, samples = read_png16(args.sequence / "depth" / f"{k:06d}.png")
            now = time.time_ns()
            _, p, q = poses[k]
            # The pose at the frame's stamp and a moment after: the pose at the stamp is exact.
            put_odometry(msgs.odometry(m, now, p, q))
            put_odometry(msgs.odometry(m, now + 1_000_000, p, q))
            time.sleep(0.05)
            little = bytearray(len(samples))  # PNG's samples are big-endian; realsense-ros sends little
            little[0::2], little[1::2] = samples[1::2], samples[0::2]
            put_info(info(now, width, height))
            time.sleep(0.02)
            put_image(image(now, width, height, "16UC1", 2 * width, bytes(little)))
            sent.append({"k": k, "stamp": now})
            time.sleep(1.0 / args.rate)

        # Two images polymap must refuse: not a depth encoding, and a size the camera_info lacks.
        now = time.time_ns()
        put_info(info(now, 2, 2))
        time.sleep(0.05)
        put_image(image(now, 2, 2, "rgb8", 6, bytes(12)))
        time.sleep(0.05)
        put_image(image(time.time_ns(), 3, 3, "16UC1", 6, bytes(18)))
        time.sleep(2.0)

        with lock:
            frames = [{"k": s["k"], "stamp": s["stamp"], "drift_z": drift.get(s["stamp"]),
                       "polygons": polygons[s["stamp"]]} for s in sent if s["stamp"] in polygons]
    print(json.dumps({"sent": len(sent), "frames": frames}))


if __name__ == "__main__":
    main()
