"""ROS 2 messages the Python test peers send, built with a rosbags typestore's classes
(`types`: `store.types`): VINS's odometry and a depth camera's camera_info and image, as
VINS-Fusion and realsense-ros fill them."""

import numpy as np


def header(types, stamp_ns, frame):
    stamp = types["builtin_interfaces/msg/Time"](sec=stamp_ns // 1_000_000_000, nanosec=stamp_ns % 1_000_000_000)
    return types["std_msgs/msg/Header"](stamp=stamp, frame_id=frame)


def odometry(types, stamp_ns, p, q):
    """nav_msgs/Odometry of the body in `world` at position p and quaternion q (x, y, z, w)."""
    zero = types["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0)
    return types["nav_msgs/msg/Odometry"](
        header=header(types, stamp_ns, "world"), child_frame_id="body",
        pose=types["geometry_msgs/msg/PoseWithCovariance"](
            pose=types["geometry_msgs/msg/Pose"](
                position=types["geometry_msgs/msg/Point"](x=p[0], y=p[1], z=p[2]),
                orientation=types["geometry_msgs/msg/Quaternion"](x=q[0], y=q[1], z=q[2], w=q[3])),
            covariance=np.zeros(36)),
        twist=types["geometry_msgs/msg/TwistWithCovariance"](
            twist=types["geometry_msgs/msg/Twist"](linear=zero, angular=zero), covariance=np.zeros(36)))


def camera_info(types, stamp_ns, frame, cam, width, height):
    """sensor_msgs/CameraInfo of a rectified camera with the sequence's intrinsics `cam`."""
    fx, fy, cx, cy = cam["fx"], cam["fy"], cam["cx"], cam["cy"]
    roi = types["sensor_msgs/msg/RegionOfInterest"](x_offset=0, y_offset=0, height=0, width=0, do_rectify=False)
    return types["sensor_msgs/msg/CameraInfo"](
        header=header(types, stamp_ns, frame), height=height, width=width, distortion_model="plumb_bob",
        d=np.zeros(5), k=np.array([fx, 0.0, cx, 0.0, fy, cy, 0.0, 0.0, 1.0]), r=np.eye(3).flatten(),
        p=np.array([fx, 0.0, cx, 0.0, 0.0, fy, cy, 0.0, 0.0, 0.0, 1.0, 0.0]), binning_x=0, binning_y=0, roi=roi)


def image(types, stamp_ns, frame, width, height, encoding, step, data):
    """sensor_msgs/Image of little-endian `data`."""
    return types["sensor_msgs/msg/Image"](header=header(types, stamp_ns, frame), height=height, width=width,
                                          encoding=encoding, is_bigendian=0, step=step,
                                          data=np.frombuffer(data, dtype=np.uint8))
