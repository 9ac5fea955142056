#!/usr/bin/env python3
"""The depth camera of tests/ros1.rs's ROS depth source test: a rospy node, sharing no code
with polymap, that publishes a sequence's depth frames as realsense-ros (ROS 1) publishes
the L515's (sensor_msgs/Image 16UC1 on /l515/depth/image_rect_raw, in the sequence's own
unit, with its camera_info), and each frame's pose on /vins_estimator/odometry as VINS would,
then two images polymap must refuse (an RGB image, a size its camera_info does not have).
It listens to polymap's frame polygons and map updates, and prints, per frame polymap
mapped: the frame's index, stamp, the map's drift then, and the polygons' outlines.
"""

import argparse
import json
import pathlib
import sys
import threading
import time

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))

import rospy  # noqa: E402
from geometry_msgs.msg import Point, Pose, PoseWithCovariance, Quaternion  # noqa: E402
from nav_msgs.msg import Odometry  # noqa: E402
from sensor_msgs.msg import CameraInfo, Image  # noqa: E402

from polymap_msgs.msg import FramePolygons, MapUpdate  # noqa: E402
from polymap_sequence import camera_toml, read_png16, read_poses  # noqa: E402


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--sequence", required=True, type=pathlib.Path)
    ap.add_argument("--frames", type=int, default=24)
    ap.add_argument("--rate", type=float, default=3.0)
    args = ap.parse_args()
    cam = camera_toml(args.sequence)
    poses = read_poses(args.sequence)

    rospy.init_node("l515_depth", disable_signals=True)
    lock = threading.Lock()
    polygons, drift = {}, {}

    def on_polygons(m):
        with lock:
            polygons[m.header.stamp.to_nsec()] = [[[p.x, p.y, p.z] for p in poly.boundary] for poly in m.polygons]

    def on_update(m):
        with lock:
            drift[m.header.stamp.to_nsec()] = m.drift_z

    subs = [rospy.Subscriber("/polymap/frame_polygons", FramePolygons, on_polygons, queue_size=100),
            rospy.Subscriber("/polymap/map_updates", MapUpdate, on_update, queue_size=100)]
    image_pub = rospy.Publisher("/l515/depth/image_rect_raw", Image, queue_size=10)
    info_pub = rospy.Publisher("/l515/depth/camera_info", CameraInfo, queue_size=10)
    odom_pub = rospy.Publisher("/vins_estimator/odometry", Odometry, queue_size=100)
    # Ready once polymap has connected to each publisher and to each subscriber's topic.
    deadline = time.time() + 60.0
    while time.time() < deadline and min(e.get_num_connections() for e in subs + [image_pub, info_pub, odom_pub]) == 0:
        time.sleep(0.05)
    if min(e.get_num_connections() for e in subs + [image_pub, info_pub, odom_pub]) == 0:
        sys.exit("polymap never connected to the depth peer's topics")

    def info(stamp, width, height):
        m = CameraInfo()
        m.header.stamp, m.header.frame_id = stamp, "l515_depth_optical_frame"
        m.width, m.height, m.distortion_model, m.D = width, height, "plumb_bob", [0.0] * 5
        m.K = [cam["fx"], 0.0, cam["cx"], 0.0, cam["fy"], cam["cy"], 0.0, 0.0, 1.0]
        m.R = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]
        m.P = [cam["fx"], 0.0, cam["cx"], 0.0, 0.0, cam["fy"], cam["cy"], 0.0, 0.0, 0.0, 1.0, 0.0]
        return m

    def odometry(stamp, p, q):
        m = Odometry()
        m.header.stamp, m.header.frame_id, m.child_frame_id = stamp, "world", "body"
        m.pose = PoseWithCovariance(pose=Pose(position=Point(*p), orientation=Quaternion(*q)))
        return m

    sent = []
    step = max(1, len(poses) // args.frames)
    for k in range(0, min(len(poses), step * args.frames), step):
        width, height, samples = read_png16(args.sequence / "depth" / f"{k:06d}.png")
        now = time.time_ns()
        stamp = rospy.Time(now // 1_000_000_000, now % 1_000_000_000)
        after = rospy.Time((now + 1_000_000) // 1_000_000_000, (now + 1_000_000) % 1_000_000_000)
        _, p, q = poses[k]
        # The pose at the frame's stamp and a moment after: the pose at the stamp is exact.
        odom_pub.publish(odometry(stamp, p, q))
        odom_pub.publish(odometry(after, p, q))
        time.sleep(0.05)
        little = bytearray(len(samples))  # PNG's samples are big-endian; realsense-ros sends little
        little[0::2], little[1::2] = samples[1::2], samples[0::2]
        image = Image(height=height, width=width, encoding="16UC1", step=width * 2, data=bytes(little))
        image.header.stamp, image.header.frame_id = stamp, "l515_depth_optical_frame"
        info_pub.publish(info(stamp, width, height))
        time.sleep(0.02)
        image_pub.publish(image)
        sent.append({"k": k, "stamp": now})
        time.sleep(1.0 / args.rate)

    # Two images polymap must refuse: not a depth encoding, and a size the camera_info lacks.
    now = rospy.Time.now()
    rgb = Image(height=2, width=2, encoding="rgb8", step=6, data=bytes(12))
    rgb.header.stamp = now
    info_pub.publish(info(now, 2, 2))
    time.sleep(0.05)
    image_pub.publish(rgb)
    time.sleep(0.05)
    small = Image(height=3, width=3, encoding="16UC1", step=6, data=bytes(18))
    small.header.stamp = rospy.Time.now()
    image_pub.publish(small)
    time.sleep(2.0)

    with lock:
        frames = [{"k": s["k"], "stamp": s["stamp"], "drift_z": drift.get(s["stamp"]), "polygons": polygons[s["stamp"]]}
                  for s in sent if s["stamp"] in polygons]
    del subs
    print(json.dumps({"sent": len(sent), "frames": frames}))
    rospy.signal_shutdown("done")


if __name__ == "__main__":
    main()
