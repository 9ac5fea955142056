#!/usr/bin/env python3
"""Writes the valid seeds (`seed-*`) of the corpora of the ROS 1 and log targets: TCPROS
headers, ROS 1 messages, XML-RPC bodies, a ROS 1 bag and an MCAP file, each as a peer or a
recorder makes them (rosbags from PyPI for the messages and logs, sharing no code with
polymap). Run with the suite's virtualenv: target/pyenv/bin/python fuzz/make_seeds.py"""

import pathlib
import struct
import tempfile

import numpy as np
from rosbags.rosbag1 import Writer as Bag1Writer
from rosbags.rosbag2 import StoragePlugin, Writer as Bag2Writer
from rosbags.typesys import Stores, get_typestore

CORPUS = pathlib.Path(__file__).resolve().parent / "corpus"


def put(target, name, data):
    (CORPUS / target).mkdir(parents=True, exist_ok=True)
    (CORPUS / target / f"seed-{name}").write_bytes(data)


def header_fields(fields):
    return b"".join(struct.pack("<I", len(f)) + f for f in (f"{k}={v}".encode() for k, v in fields))


def messages(store, ros1):
    T = store.types
    stamp = T["builtin_interfaces/msg/Time"](sec=1, nanosec=500)
    hdr = (lambda frame: T["std_msgs/msg/Header"](seq=3, stamp=stamp, frame_id=frame)) if ros1 else \
        (lambda frame: T["std_msgs/msg/Header"](stamp=stamp, frame_id=frame))
    zero = T["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0)
    pose = T["geometry_msgs/msg/Pose"](position=T["geometry_msgs/msg/Point"](x=1.0, y=2.0, z=0.9),
                                       orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0))
    odometry = T["nav_msgs/msg/Odometry"](
        header=hdr("world"), child_frame_id="body",
        pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=np.zeros(36)),
        twist=T["geometry_msgs/msg/TwistWithCovariance"](
            twist=T["geometry_msgs/msg/Twist"](linear=zero, angular=zero), covariance=np.zeros(36)))
    stamped = T["geometry_msgs/msg/PoseStamped"](header=hdr("world"), pose=pose)
    w, h = 8, 6
    roi = T["sensor_msgs/msg/RegionOfInterest"](x_offset=0, y_offset=0, height=0, width=0, do_rectify=False)
    k = np.array([5.0, 0.0, 4.0, 0.0, 5.0, 3.0, 0.0, 0.0, 1.0])
    info_fields = dict(header=hdr("depth"), height=h, width=w, distortion_model="plumb_bob", d=np.zeros(5),
                       r=np.eye(3).flatten(), binning_x=0, binning_y=0, roi=roi)
    if ros1:
        info = T["sensor_msgs/msg/CameraInfo"](K=k, R=info_fields.pop("r"), P=np.zeros(12), D=info_fields.pop("d"),
                                               **info_fields)
    else:
        info = T["sensor_msgs/msg/CameraInfo"](k=k, p=np.zeros(12), **info_fields)
    depth = (np.arange(w * h, dtype="<u2") * 7 + 900).tobytes()
    image = T["sensor_msgs/msg/Image"](header=hdr("depth"), height=h, width=w, encoding="16UC1", is_bigendian=0,
                                       step=2 * w, data=np.frombuffer(depth, dtype=np.uint8))
    return {"odometry": ("/odometry", odometry), "pose_stamped": ("/vins/pose", stamped),
            "camera_info": ("/camera/depth/camera_info", info), "image": ("/camera/depth/image_rect_raw", image)}


def main():
    put("tcpros_header", "subscriber", header_fields(
        [("callerid", "/planner"), ("topic", "/polygon_new_markers"), ("tcp_nodelay", "1"),
         ("md5sum", "d155b9ce5188fbaf89745847fd5882d7"), ("type", "visualization_msgs/MarkerArray")]))
    put("tcpros_header", "service", header_fields(
        [("callerid", "/planner"), ("service", "/polymap/get_map"), ("md5sum", "*"), ("persistent", "1")]))
    put("xmlrpc", "call", b"<?xml version='1.0'?><methodCall><methodName>publisherUpdate</methodName><params>"
        b"<param><value><string>/master</string></value></param><param><value><string>/odometry</string></value></param>"
        b"<param><value><array><data><value><string>http://127.0.0.1:40123/</string></value></data></array></value>"
        b"</param></params></methodCall>")
    put("xmlrpc", "response", b"<?xml version='1.0'?><methodResponse><params><param><value><array><data>"
        b"<value><i4>1</i4></value><value>ok</value><value><array><data><value>TCPROS</value><value>127.0.0.1</value>"
        b"<value><int>41234</int></value></data></array></value></data></array></value></param></params></methodResponse>")
    put("xmlrpc", "uri", b"<?xml version='1.0'?><methodResponse><params><param><value><array><data>"
        b"<value><i4>1</i4></value><value><string></string></value><value><string>http://robot:11311/</string></value>"
        b"</data></array></value></param></params></methodResponse>")

    ros1 = get_typestore(Stores.ROS1_NOETIC)
    ros1_msgs = messages(ros1, True)
    for name, (_, msg) in ros1_msgs.items():
        put("ros1_message", name, bytes(ros1.serialize_ros1(msg, msg.__msgtype__)))

    with tempfile.TemporaryDirectory() as tmp:
        path = pathlib.Path(tmp) / "seed.bag"
        with Bag1Writer(path) as w:
            for t, (name, (topic, msg)) in enumerate(ros1_msgs.items()):
                c = w.add_connection(topic, msg.__msgtype__, typestore=ros1)
                w.write(c, 1_000_000_000 + t, bytes(ros1.serialize_ros1(msg, msg.__msgtype__)))
        put("bag", "four-topics", path.read_bytes())

        ros2 = get_typestore(Stores.ROS2_HUMBLE)
        out = pathlib.Path(tmp) / "seed"
        with Bag2Writer(out, version=9, storage_plugin=StoragePlugin.MCAP) as w:
            for t, (name, (topic, msg)) in enumerate(messages(ros2, False).items()):
                c = w.add_connection(topic, msg.__msgtype__, typestore=ros2)
                w.write(c, 1_000_000_000 + t, bytes(ros2.serialize_cdr(msg, msg.__msgtype__)))
        put("mcap", "four-topics", next(out.glob("*.mcap")).read_bytes())


if __name__ == "__main__":
    main()
