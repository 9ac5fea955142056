#!/usr/bin/env python3
"""What VINS-Fusion gets from polymap's D435i (real or mock): the IR pair, their camera
infos and the united IMU on realsense-ros's topics, received as a ROS 2 node on rmw_zenoh
receives them (rmw_zenoh.py beside this file) and decoded with rosbags.

    pip install eclipse-zenoh==1.10.2 rosbags==0.11.9
    python3 examples/python/vins_feed.py [--connect tcp/127.0.0.1:7447] [--namespace /camera/camera]

Prints one JSON object summarising what arrived; exits non-zero if a stream is missing
within the timeout.
"""

import argparse
import json
import queue
import sys
import time

from rmw_zenoh import Peer, connect_from_env

TYPES = {
    "imu": "sensor_msgs/msg/Imu",
    "infra1/image_rect_raw": "sensor_msgs/msg/Image",
    "infra2/image_rect_raw": "sensor_msgs/msg/Image",
    "infra1/camera_info": "sensor_msgs/msg/CameraInfo",
    "infra2/camera_info": "sensor_msgs/msg/CameraInfo",
}


def summary(topic, m):
    stamp = m.header.stamp.sec + m.header.stamp.nanosec * 1e-9
    if topic == "imu":
        a, w = m.linear_acceleration, m.angular_velocity
        stamp_ns = int(m.header.stamp.sec) * 1_000_000_000 + int(m.header.stamp.nanosec)
        return {"stamp": stamp, "stamp_ns": stamp_ns, "frame_id": m.header.frame_id, "accel": [a.x, a.y, a.z], "gyro": [w.x, w.y, w.z],
                "orientation_covariance": [float(v) for v in m.orientation_covariance],
                "angular_velocity_covariance": [float(v) for v in m.angular_velocity_covariance],
                "linear_acceleration_covariance": [float(v) for v in m.linear_acceleration_covariance]}
    if topic.endswith("image_rect_raw"):
        data = bytes(m.data)
        return {"stamp": stamp, "frame_id": m.header.frame_id, "width": int(m.width), "height": int(m.height),
                "encoding": m.encoding, "step": int(m.step), "bytes": len(data), "grey_levels": len(set(data))}
    return {"stamp": stamp, "frame_id": m.header.frame_id, "width": int(m.width), "height": int(m.height),
            "k": [float(v) for v in m.k], "p": [float(v) for v in m.p]}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--connect", default=connect_from_env())
    ap.add_argument("--namespace", default="/camera/camera")
    ap.add_argument("--imu", type=int, default=100, help="IMU samples to wait for")
    ap.add_argument("--timeout", type=float, default=20.0)
    args = ap.parse_args()

    with Peer(args.connect, node="vins_estimator") as peer:
        return run(peer, args)


def run(peer, args):
    received = queue.Queue()
    for topic, typename in TYPES.items():
        peer.subscribe(f"{args.namespace}/{topic}", typename,
                       lambda m, att, topic=topic: received.put((topic, m, att)))
    first, imu, attachments = {}, [], {}
    deadline = time.time() + args.timeout
    while (len(first) < len(TYPES) or len(imu) < args.imu) and time.time() < deadline:
        try:
            topic, m, att = received.get(timeout=0.1)
        except queue.Empty:
            continue
        s = summary(topic, m)
        if topic == "imu":
            imu.append(s)
        first.setdefault(topic, s)
        attachments.setdefault(topic, []).append(att)
    stamps = [s["stamp"] for s in imu]
    out = {
        "streams": first,
        "imu_count": len(imu),
        "imu_rate_hz": (len(stamps) - 1) / (stamps[-1] - stamps[0]) if len(stamps) > 1 and stamps[-1] > stamps[0] else 0.0,
        # The sensor's own period, from its stamps: a sample lost on the way leaves one gap.
        "imu_median_interval_s": 1e-9 * sorted(b["stamp_ns"] - a["stamp_ns"] for a, b in zip(imu, imu[1:]))[len(imu) // 2 - 1]
        if len(imu) > 2 else 0.0,
        "imu_mean_accel_norm": sum(sum(v * v for v in s["accel"]) ** 0.5 for s in imu) / max(len(imu), 1),
        # rmw_zenoh's attachment on every sample: sequence numbers counting up per publisher.
        "attachments_ok": {t: all(a is not None for a in atts) and all(
            b[0] > a[0] for a, b in zip(atts, atts[1:]) if a[2] == b[2]) for t, atts in attachments.items()},
    }
    print(json.dumps(out))
    return 0 if len(first) == len(TYPES) and len(imu) >= args.imu else 1


if __name__ == "__main__":
    sys.exit(main())
