#!/usr/bin/env python3
"""ROS 1 bags for tests/ros1.rs, with Debian's rosbag (Noetic's), sharing no code with polymap.

- `write-absurd OUT.bag`: nav_msgs/Odometry on /vins_estimator/odometry whose positions are
  not finite, for `rosbag play` (roscpp) to send to polymap.
- `write-sequence OUT.bag SEQ COMPRESSION`: a polymap sequence as the robot's stack records
  it: the depth frames as realsense-ros publishes the L515's (16UC1 in millimetres, REP 118)
  with their camera_info, and each frame's pose as VINS-Fusion's odometry, chunks
  compressed as asked (none, bz2, lz4).
- `write-large OUT.bag SEQ MB`: a bag of about MB megabytes, mostly the D435i's IR images as a
  robot records them beside the depth, the sequence walked forward and back.
- `write-topicless OUT.bag`: a bag with only /tf.
- `read IN.bag`: what `rosbag record` (roscpp) kept of polymap's topics, decoded with the
  classes rosbag makes from the definitions polymap sent (polymap_msgs is not installed
  where this runs), as one JSON object.
"""

import json
import pathlib
import sys

import rosbag
import rospy
from nav_msgs.msg import Odometry
from sensor_msgs.msg import CameraInfo, Image
from tf2_msgs.msg import TFMessage

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from polymap_sequence import camera_toml, read_png16, read_poses  # noqa: E402


def write_absurd(path):
    with rosbag.Bag(path, "w") as bag:
        for k in range(5):
            m = Odometry()
            m.header.stamp = rospy.Time(1_700_000_000 + k, 0)
            m.header.frame_id = "world"
            m.pose.pose.position.x = float("nan")
            m.pose.pose.orientation.w = 1.0
            bag.write("/vins_estimator/odometry", m, m.header.stamp)


def millimetres(seq, k, cam):
    """Frame k's depth as 16UC1 millimetres (REP 118): (width, height, little-endian bytes)."""
    width, height, samples = read_png16(seq / "depth" / f"{k:06d}.png")
    mm = bytearray(2 * width * height)
    for i in range(width * height):
        v = round(((samples[2 * i] << 8) | samples[2 * i + 1]) * cam["depth_scale"] * 1000.0)
        mm[2 * i], mm[2 * i + 1] = v & 0xFF, v >> 8
    return width, height, bytes(mm)


def write_frame(bag, stamp_ns, p, q, depth, cam):
    """One frame as the robot's stack records it: VINS's odometry, the L515's camera_info and depth."""
    width, height, mm = depth
    stamp = rospy.Time(stamp_ns // 1_000_000_000, stamp_ns % 1_000_000_000)
    odom = Odometry()
    odom.header.stamp, odom.header.frame_id, odom.child_frame_id = stamp, "world", "body"
    (odom.pose.pose.position.x, odom.pose.pose.position.y, odom.pose.pose.position.z) = p
    (odom.pose.pose.orientation.x, odom.pose.pose.orientation.y, odom.pose.pose.orientation.z,
     odom.pose.pose.orientation.w) = q
    bag.write("/vins_estimator/odometry", odom, stamp)
    info = CameraInfo(width=width, height=height, distortion_model="plumb_bob", D=[0.0] * 5,
                      K=[cam["fx"], 0.0, cam["cx"], 0.0, cam["fy"], cam["cy"], 0.0, 0.0, 1.0])
    info.header.stamp = stamp
    bag.write("/l515/depth/camera_info", info, stamp)
    image = Image(height=height, width=width, encoding="16UC1", step=2 * width, data=mm)
    image.header.stamp, image.header.frame_id = stamp, "l515_depth_optical_frame"
    bag.write("/l515/depth/image_rect_raw", image, stamp)
    return stamp


def write_sequence(path, seq, compression):
    seq = pathlib.Path(seq)
    cam = camera_toml(seq)
    with rosbag.Bag(path, "w", compression=compression) as bag:
        for k, (stamp_ns, p, q) in enumerate(read_poses(seq)):
            write_frame(bag, stamp_ns, p, q, millimetres(seq, k, cam), cam)


def write_large(path, seq, megabytes):
    """A robot's bag of about MEGABYTES: the sequence walked forward and back at 30 Hz, each
    frame with the D435i's two IR images (848x480 mono8, as realsense-ros records them for
    VINS), until the bag is that large."""
    seq = pathlib.Path(seq)
    cam = camera_toml(seq)
    poses = read_poses(seq)
    depths = [millimetres(seq, k, cam) for k in range(len(poses))]
    ir = bytes(range(256)) * (848 * 480 // 256)
    order = list(range(len(poses))) + list(range(len(poses) - 2, 0, -1))
    size, limit, step = 0, int(megabytes) * 1_000_000, 0
    with rosbag.Bag(path, "w") as bag:
        while size < limit:
            k = order[step % len(order)]
            stamp = write_frame(bag, 1_000_000_000 + step * 33_333_333, poses[k][1], poses[k][2], depths[k], cam)
            for index in (1, 2):
                image = Image(height=480, width=848, encoding="mono8", step=848, data=ir)
                image.header.stamp, image.header.frame_id = stamp, f"camera_infra{index}_optical_frame"
                bag.write(f"/camera/infra{index}/image_rect_raw", image, stamp)
            size += 2 * len(ir) + len(depths[k][2])
            step += 1


def write_topicless(path):
    with rosbag.Bag(path, "w") as bag:
        for k in range(3):
            bag.write("/tf", TFMessage(), rospy.Time(1_700_000_000 + k, 0))


def read(path):
    out = {"topics": {}, "map_polygons": 0, "marker_points": 0, "status_processed": 0}
    with rosbag.Bag(path) as bag:
        info = bag.get_type_and_topic_info()
        for topic, t in info.topics.items():
            out["topics"][topic] = {"type": t.msg_type, "count": t.message_count}
        for topic, msg, _ in bag.read_messages():
            if topic == "/polymap/map":
                out["map_polygons"] = max(out["map_polygons"], len(msg.polygons))
                out["map_class"] = type(msg).__module__
            elif topic == "/polygon_new_markers":
                out["marker_points"] += sum(len(m.points) for m in msg.markers)
            elif topic == "/polymap/status":
                out["status_processed"] = max(out["status_processed"], msg.frames_processed)
    print(json.dumps(out))


if __name__ == "__main__":
    commands = {"write-absurd": write_absurd, "write-sequence": write_sequence, "write-large": write_large,
                "write-topicless": write_topicless, "read": read}
    commands[sys.argv[1]](*sys.argv[2:])
