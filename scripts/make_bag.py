"""Records synthetic data as librealsense .bag files, the way recordings made with
realsense-viewer look, so the tests play them back through the same driver code as the
robot (realsense-rust over librealsense). L515-like: a polymap sequence's depth, one Z16 stream with the sequence's intrinsics,
  its depth units as the sensor's depth_units option, stamps in the global time domain.
      python make_bag.py SEQ OUT.bag [--frames N]

Uses pyrealsense2's software_device and recorder (librealsense's own bag writer).
"""

import argparse
import pathlib
import tomllib

import numpy as np
import pyrealsense2 as rs
from PIL import Image


def read_stamps(poses_txt: pathlib.Path) -> list[float]:
    stamps = []
    for line in poses_txt.read_text().splitlines():
        if line.strip() and not line.startswith("#"):
            stamps.append(float(line.split()[0]))
    return stamps


def pinhole(width, height, fx, fy, cx, cy):
    intr = rs.intrinsics()
    intr.width, intr.height = width, height
    intr.fx, intr.fy, intr.ppx, intr.ppy = fx, fy, cx, cy
    intr.model = rs.distortion.none
    intr.coeffs = [0.0] * 5
    return intr


def stamp(frame, stamp_ns, number):
    frame.timestamp = stamp_ns * 1e-6  # librealsense stamps are milliseconds
    frame.domain = rs.timestamp_domain.global_time
    frame.frame_number = number


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("sequence", type=pathlib.Path)
    ap.add_argument("out", type=pathlib.Path)
    ap.add_argument("--frames", type=int, default=0, help="first N frames only (0 = all)")
    args = ap.parse_args()

    cam = tomllib.loads((args.sequence / "camera.toml").read_text())
    stamps = read_stamps(args.sequence / "poses.txt")
    if args.frames:
        stamps = stamps[: args.frames]
    fps = round((len(stamps) - 1) / (stamps[-1] - stamps[0])) if len(stamps) > 1 else 30

    intr = pinhole(cam["width"], cam["height"], cam["fx"], cam["fy"], cam["cx"], cam["cy"])

    device = rs.software_device()
    device.register_info(rs.camera_info.name, "Intel RealSense L515 (polymap synthetic)")
    device.register_info(rs.camera_info.serial_number, "f0000000")
    sensor = device.add_sensor("L500 Depth Sensor")
    stream = rs.video_stream()
    stream.type, stream.index, stream.uid = rs.stream.depth, 0, 0
    stream.width, stream.height, stream.fps = intr.width, intr.height, fps
    stream.bpp, stream.fmt, stream.intrinsics = 2, rs.format.z16, intr
    profile = sensor.add_video_stream(stream).as_video_stream_profile()
    sensor.add_read_only_option(rs.option.depth_units, cam["depth_scale"])

    args.out.parent.mkdir(parents=True, exist_ok=True)
    recorder = rs.recorder(str(args.out), device)
    queue = rs.frame_queue(len(stamps) + 1)
    sensor.open(profile)
    sensor.start(queue)
    for k, stamp_s in enumerate(stamps):
        depth = np.asarray(Image.open(args.sequence / "depth" / f"{k:06d}.png"), dtype=np.uint16)
        frame = rs.software_video_frame()
        frame.pixels = np.ascontiguousarray(depth)
        frame.bpp, frame.stride = 2, 2 * intr.width
        stamp(frame, round(stamp_s * 1e9), k)
        frame.profile = profile
        sensor.on_video_frame(frame)
        queue.wait_for_frame(5000)
    sensor.stop()
    sensor.close()
    del recorder  # closing the recorder writes the bag's index
    print(f"{args.out}: {len(stamps)} depth frames {intr.width}x{intr.height} @ {fps} fps")


if __name__ == "__main__":
    main()
