#!/usr/bin/env python3
"""ROS 1 bags for tests/ros1.rs, with Debian's rosbag (Noetic's), sharing no code with polymap.

- `write-absurd OUT.bag`: nav_msgs/Odometry on /vins_estimator/odometry whose positions are
  not finite, for `rosbag play` (roscpp) to send to polymap.
- `read IN.bag`: what `rosbag record` (roscpp) kept of polymap's topics, decoded with the
  classes rosbag makes from the definitions polymap sent (polymap_msgs is not installed
  where this runs), as one JSON object.
"""

import json
import sys

import rosbag
import rospy
from nav_msgs.msg import Odometry


def write_absurd(path):
    with rosbag.Bag(path, "w") as bag:
        for k in range(5):
            m = Odometry()
            m.header.stamp = rospy.Time(1_700_000_000 + k, 0)
            m.header.frame_id = "world"
            m.pose.pose.position.x = float("nan")
            m.pose.pose.orientation.w = 1.0
            bag.write("/vins_estimator/odometry", m, m.header.stamp)


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
    {"write-absurd": write_absurd, "read": read}[sys.argv[1]](sys.argv[2])
