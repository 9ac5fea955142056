#!/usr/bin/env python3
"""What VINS-Fusion gets from polymap's D435i (real or mock): the IR pair, their camera
infos and the united IMU, as realsense-ros publishes them, decoded with rosbags.

    pip install eclipse-zenoh==1.10.2 rosbags==0.11.9
    python3 examples/python/vins_feed.py [--connect tcp/127.0.0.1:7447] [--prefix camera/camera]

Prints one JSON object summarising what arrived; exits non-zero if a stream is missing
within the timeout.
"""

import argparse
import json
import sys
import time

import zenoh
from rosbags.typesys import Stores, get_typestore

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
    ap.add_argument("--connect", default="tcp/127.0.0.1:7447")
    ap.add_argument("--prefix", default="camera/camera")
    ap.add_argument("--imu", type=int, default=100, help="IMU samples to wait for")
    ap.add_argument("--timeout", type=float, default=20.0)
    args = ap.parse_args()

    store = get_typestore(Stores.ROS2_HUMBLE)
    conf = zenoh.Config.from_json5(json.dumps({
        "mode": "peer",
        "connect": {"endpoints": [args.connect]},
        "listen": {"endpoints": ["tcp/127.0.0.1:0"]},
        "scouting": {"multicast": {"enabled": False}},
    }))
    first, imu = {}, []
    with zenoh.open(conf) as session:
        sub = session.declare_subscriber(f"{args.prefix}/**")
        deadline = time.time() + args.timeout
        while (len(first) < len(TYPES) or len(imu) < args.imu) and time.time() < deadline:
            sample = sub.try_recv()
            if sample is None:
                time.sleep(0.01)
                continue
            topic = str(sample.key_expr)[len(args.prefix) + 1:]
            if topic not in TYPES:
                continue
            m = store.deserialize_cdr(sample.payload.to_bytes(), TYPES[topic])
            s = summary(topic, m)
            if topic == "imu":
                imu.append(s)
            first.setdefault(topic, s)
    stamps = [s["stamp"] for s in imu]
    out = {
        "streams": first,
        "imu_count": len(imu),
        "imu_rate_hz": (len(stamps) - 1) / (stamps[-1] - stamps[0]) if len(stamps) > 1 and stamps[-1] > stamps[0] else 0.0,
        "imu_mean_accel_norm": sum(sum(v * v for v in s["accel"]) ** 0.5 for s in imu) / max(len(imu), 1),
    }
    print(json.dumps(out))
    return 0 if len(first) == len(TYPES) and len(imu) >= args.imu else 1


if __name__ == "__main__":
    sys.exit(main())
