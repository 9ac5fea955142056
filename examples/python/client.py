#!/usr/bin/env python3
"""A planner-side client in Python: asks polymap for its map and a foothold, and reads its
RViz markers, as a ROS 2 node on rmw_zenoh would (rmw_zenoh.py beside this file: Zenoh from
PyPI, rosbags for the CDR and the type hashes, polymap_msgs from polymap_msgs/).

    pip install eclipse-zenoh==1.10.2 rosbags==0.11.9
    python3 examples/python/client.py [--connect tcp/127.0.0.1:7447] [--namespace /polymap/leju]

Prints one JSON object: the map's polygons (id, label, step, area, centroid), the foothold
under a point of the bundled stairs' second tread, and the first MarkerArray received.
Exits non-zero if any does not arrive within the timeout.
"""

import argparse
import json
import sys
import threading
import time

from rmw_zenoh import Peer, connect_from_env

LABELS = {0: "none", 1: "floor", 2: "tread", 3: "landing", 4: "riser", 5: "wall", 6: "slope"}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--connect", default=connect_from_env())
    ap.add_argument("--namespace", default="/polymap/leju")
    ap.add_argument("--timeout", type=float, default=20.0)
    args = ap.parse_args()

    with Peer(args.connect, node="planner_client") as peer:
        return run(peer, args)


def run(peer, args):
    ns = args.namespace.rstrip("/")
    out, got_markers = {}, threading.Event()

    def on_markers(a, _attachment):
        if a.markers and not got_markers.is_set():
            k = a.markers[0]
            out["markers"] = {"count": len(a.markers), "ns": k.ns, "id": int(k.id), "type": int(k.type),
                              "points": len(k.points), "frame_id": k.header.frame_id}
            got_markers.set()

    peer.subscribe(f"{ns}/markers", "visualization_msgs/msg/MarkerArray", on_markers)
    get_map = peer.client(f"{ns}/get_map", "polymap_msgs/srv/GetMap")
    get_foothold = peer.client(f"{ns}/get_foothold", "polymap_msgs/srv/GetFoothold")
    Request = peer.msg("polymap_msgs/srv/GetMap_Request")
    FootholdRequest = peer.msg("polymap_msgs/srv/GetFoothold_Request")
    Point = peer.msg("geometry_msgs/msg/Point")
    deadline = time.time() + args.timeout
    while "foothold" not in out and time.time() < deadline:
        try:
            response, _, _, _ = get_map(Request(structure_needs_at_least_one_member=0), timeout=2.0)
            m = response.map
            if not m.polygons:
                time.sleep(0.5)
                continue
            out["map"] = {"frame_id": m.header.frame_id, "drift_z": m.drift_z, "polygons": [
                {"id": int(p.id), "label": LABELS.get(int(p.label), "?"), "step": int(p.step), "area": p.area,
                 "centroid": [p.centroid.x, p.centroid.y, p.centroid.z], "vertices": len(p.boundary),
                 "convex_pieces": len(p.convex_pieces)}
                for p in m.polygons]}
            response, _, _, _ = get_foothold(FootholdRequest(point=Point(x=0.42, y=0.0, z=0.30)), timeout=2.0)
            f = response.foothold
            out["foothold"] = {"found": bool(f.found), "contains": bool(f.contains), "polygon_id": int(f.polygon_id),
                               "label": LABELS.get(int(f.label), "?"), "piece": len(f.piece), "distance": f.distance}
        except (TimeoutError, RuntimeError) as e:
            print(f"waiting for polymap: {e}", file=sys.stderr)
            time.sleep(0.5)
    got_markers.wait(max(0.0, deadline - time.time()))
    print(json.dumps(out))
    return 0 if all(k in out for k in ("map", "foothold", "markers")) else 1


if __name__ == "__main__":
    sys.exit(main())
