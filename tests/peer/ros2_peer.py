#!/usr/bin/env python3
"""The ROS 2 peer of tests/ros2_peer.rs: a node on rmw_zenoh written from rmw_zenoh's
design document (examples/python/rmw_zenoh.py), sharing no code with polymap. Against a
running polymap (mock camera, mock D435i, no VINS) it:

- publishes VINS's odometry on /odometry: each pose of the sequence the mock camera replays,
  stamped when the loop shows that frame (the mock camera's clock, rebuilt from poses.txt);
- subscribes to polymap's topics and the D435i's, as rmw_zenoh declares subscriptions, and
  checks every sample's attachment;
- reads the ROS graph from the liveliness tokens;
- calls get_map and get_foothold;
- reads the planar terrain with convex_plane_decomposition_msgs and grid_map_msgs as their
  ROS 2 .msg files define them (below, registered with rosbags).

Prints one JSON object with what it saw.
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
from vins_schedule import Schedule  # noqa: E402
from rosbags.typesys import get_types_from_msg  # noqa: E402

# The packages' ROS 2 message definitions (grid_map jazzy; leggedrobotics' plane_segmentation
# for ROS 2), as their .msg files write them.
TERRAIN_MSGS = {
    "grid_map_msgs/msg/GridMapInfo": "float64 resolution\nfloat64 length_x\nfloat64 length_y\ngeometry_msgs/Pose pose\n",
    "grid_map_msgs/msg/GridMap": "std_msgs/Header header\nGridMapInfo info\nstring[] layers\nstring[] basic_layers\n"
                                 "std_msgs/Float32MultiArray[] data\nuint16 outer_start_index\nuint16 inner_start_index\n",
    "convex_plane_decomposition_msgs/msg/Point2d": "float32 x\nfloat32 y\n",
    "convex_plane_decomposition_msgs/msg/Polygon2d": "Point2d[] points\n",
    "convex_plane_decomposition_msgs/msg/PolygonWithHoles2d": "Polygon2d outer_boundary\nPolygon2d[] holes\n",
    "convex_plane_decomposition_msgs/msg/BoundingBox2d": "float32 min_x\nfloat32 min_y\nfloat32 max_x\nfloat32 max_y\n",
    "convex_plane_decomposition_msgs/msg/PlanarRegion": "geometry_msgs/Pose plane_parameters\nBoundingBox2d bbox2d\n"
                                                        "PolygonWithHoles2d boundary\nPolygonWithHoles2d[] insets\n",
    "convex_plane_decomposition_msgs/msg/PlanarTerrain": "PlanarRegion[] planar_regions\ngrid_map_msgs/GridMap gridmap\n",
}
TERRAIN = "/convex_plane_decomposition_ros/planar_terrain"

NS = "/polymap/leju"
TOPICS = {
    f"{NS}/frame_polygons": "polymap_msgs/msg/FramePolygons",
    f"{NS}/map_updates": "polymap_msgs/msg/MapUpdate",
    f"{NS}/markers": "visualization_msgs/msg/MarkerArray",
    f"{NS}/status": "polymap_msgs/msg/Status",
    f"{NS}/map": "polymap_msgs/msg/Map",
    "/tf": "tf2_msgs/msg/TFMessage",
    TERRAIN: "convex_plane_decomposition_msgs/msg/PlanarTerrain",
    "/camera/camera/infra1/image_rect_raw": "sensor_msgs/msg/Image",
    "/camera/camera/infra1/camera_info": "sensor_msgs/msg/CameraInfo",
    "/camera/camera/imu": "sensor_msgs/msg/Imu",
}


class Stream:
    """What arrived on one topic, and whether its attachments were rmw_zenoh's."""

    def __init__(self):
        self.count, self.bad_attachments, self.gaps, self.last = 0, 0, 0, None
        self.first = None
        self.last_seq = {}

    def take(self, msg, att):
        self.count += 1
        self.last = msg
        if self.first is None:
            self.first = msg
        if att is None or abs(att[1] - time.time_ns()) > 5_000_000_000:
            self.bad_attachments += 1
            return
        seq, _, gid = att
        if gid in self.last_seq and seq != self.last_seq[gid] + 1:
            self.gaps += 1
        self.last_seq[gid] = seq


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--connect", required=True)
    ap.add_argument("--sequence", required=True, type=pathlib.Path)
    ap.add_argument("--seconds", type=float, default=12.0)
    args = ap.parse_args()

    with Peer(args.connect, node="ros2_peer") as peer:
        run(peer, args)


def terrain_summary(t):
    """What the planar terrain holds, as a planner reading it would check it."""
    g = t.gridmap
    layers = list(g.layers)
    rows, cols = round(g.info.length_x / g.info.resolution), round(g.info.length_y / g.info.resolution)
    elevation = g.data[layers.index("elevation")]
    finite = [float(v) for v in elevation.data if v == v]

    def signed_area(poly):
        p = poly.points
        return sum(p[i].x * p[(i + 1) % len(p)].y - p[(i + 1) % len(p)].x * p[i].y for i in range(len(p))) / 2

    return {
        "frame_id": g.header.frame_id, "layers": layers, "rows": rows, "cols": cols,
        "dims": [[d.label, int(d.size), int(d.stride)] for d in elevation.layout.dim],
        "data_lengths": [len(d.data) for d in g.data], "finite_cells": len(finite),
        "elevation_range": [min(finite), max(finite)] if finite else None,
        "regions": len(t.planar_regions),
        "regions_with_insets": sum(1 for r in t.planar_regions if len(r.insets) > 0),
        "outlines_ccw": all(signed_area(r.boundary.outer_boundary) > 0 for r in t.planar_regions),
        "holes_cw": all(signed_area(h) < 0 for r in t.planar_regions for h in r.boundary.holes),
        "unit_quaternions": all(abs(sum(v * v for v in (r.plane_parameters.orientation.x, r.plane_parameters.orientation.y,
                                                        r.plane_parameters.orientation.z, r.plane_parameters.orientation.w)) - 1) < 1e-6
                                for r in t.planar_regions),
    }


def run(peer, args):
    for name, text in TERRAIN_MSGS.items():
        peer.store.register(get_types_from_msg(text, name))
    streams = {name: Stream() for name in TOPICS}
    lock = threading.Lock()

    def taker(name):
        def take(msg, att):
            with lock:
                streams[name].take(msg, att)
        return take

    for name, typename in TOPICS.items():
        peer.subscribe(name, typename, taker(name))

    schedule = Schedule(args.sequence)
    put = peer.publisher("/odometry", "nav_msgs/msg/Odometry", qos="::,100:,:,:,,")
    m = peer.store.types

    def odometry(stamp, p, q):
        return msgs.odometry(m, stamp, p, q)

    peer.wait_for("MS", "/odometry")  # polymap's subscription is in the graph
    published = 0
    start = time.time()
    # The baseline: the first status a second after polymap first counted a pose of ours, so
    # frames taken before the poses flowed are behind it whatever the machine's load.
    status_early, first_accepted_at = None, None
    while time.time() - start < args.seconds:
        for shown, p, q in schedule.due(time.time_ns()):
            put(odometry(shown, p, q))
            published += 1
        if status_early is None:
            with lock:
                last = streams[f"{NS}/status"].last
            if first_accepted_at is None and last is not None and last.poses_accepted > 0:
                first_accepted_at = time.time()
            elif first_accepted_at is not None and time.time() - first_accepted_at > 1.0:
                status_early = last
        time.sleep(0.003)

    graph = peer.graph()
    get_map = peer.client(f"{NS}/get_map", "polymap_msgs/srv/GetMap")
    response, reply_att, seq, gid = get_map(peer.msg("polymap_msgs/srv/GetMap_Request")(structure_needs_at_least_one_member=0))
    get_foothold = peer.client(f"{NS}/get_foothold", "polymap_msgs/srv/GetFoothold")
    point = m["geometry_msgs/msg/Point"](x=0.42, y=0.0, z=0.30)
    f_response, f_att, f_seq, f_gid = get_foothold(peer.msg("polymap_msgs/srv/GetFoothold_Request")(point=point))
    with lock:
        status = streams[f"{NS}/status"].last
        out = {
            "odometry_published": published,
            "streams": {n: {"count": s.count, "bad_attachments": s.bad_attachments, "gaps": s.gaps} for n, s in streams.items()},
            "keys": {n: peer.key(n, t) for n, t in TOPICS.items()},
            "hashes": {t: peer.type_hash(t) for t in sorted(set(TOPICS.values()) | {"nav_msgs/msg/Odometry", "polymap_msgs/srv/GetMap", "polymap_msgs/srv/GetFoothold"})},
            "terrain": None if streams[TERRAIN].last is None else terrain_summary(streams[TERRAIN].last),
            "tf_last": None if streams["/tf"].last is None else {
                "parent": streams["/tf"].last.transforms[0].header.frame_id,
                "child": streams["/tf"].last.transforms[0].child_frame_id,
                "z": streams["/tf"].last.transforms[0].transform.translation.z},
            "graph": graph,
            "status_early": None if status_early is None else {"processed": int(status_early.frames_processed), "without_pose": int(status_early.frames_without_pose)},
            "status_last": None if status is None else {"processed": int(status.frames_processed), "without_pose": int(status.frames_without_pose), "poses_accepted": int(status.poses_accepted), "poses_refused": int(status.poses_refused)},
            "imu_first": None if streams["/camera/camera/imu"].first is None else {
                "angular_velocity_covariance": [float(v) for v in streams["/camera/camera/imu"].first.angular_velocity_covariance],
                "frame_id": streams["/camera/camera/imu"].first.header.frame_id},
            "image_first": None if streams["/camera/camera/infra1/image_rect_raw"].first is None else {
                "width": int(streams["/camera/camera/infra1/image_rect_raw"].first.width),
                "encoding": streams["/camera/camera/infra1/image_rect_raw"].first.encoding},
            "map": {"polygons": len(response.map.polygons), "frame_id": response.map.header.frame_id,
                    "treads": sum(1 for p in response.map.polygons if int(p.label) == 2),
                    "steppable_treads": sum(1 for p in response.map.polygons if int(p.label) == 2 and bool(p.steppable)),
                    # steppable says footing == FOOTING_STEPPABLE (0), and footing is one of the three.
                    "footing_consistent": all(bool(p.steppable) == (int(p.footing) == 0) and int(p.footing) in (0, 1, 2)
                                              for p in response.map.polygons)},
            "map_reply": {"attachment": reply_att is not None, "echoes_seq": reply_att is not None and reply_att[0] == seq,
                          "echoes_gid": reply_att is not None and reply_att[2] == gid},
            "foothold": {"found": bool(f_response.foothold.found), "contains": bool(f_response.foothold.contains),
                         "label": int(f_response.foothold.label),
                         "echoes": f_att is not None and f_att[0] == f_seq and f_att[2] == f_gid},
        }
    print(json.dumps(out))


if __name__ == "__main__":
    main()
