#!/usr/bin/env python3
"""A planner-side client in Python: asks polymap for its map and reads its RViz markers.

Zenoh from PyPI (eclipse-zenoh) carries the bytes; rosbags decodes the ROS 2 CDR, with
polymap's own messages registered from msg/*.msg.

    pip install eclipse-zenoh==1.10.2 rosbags==0.11.9
    python3 examples/python/client.py [--connect tcp/127.0.0.1:7447] [--prefix polymap/leju]

Prints one JSON object: the map's polygons (id, label, step, area, centroid) and the first
MarkerArray received. Exits non-zero if either does not arrive within the timeout.
"""

import argparse
import json
import pathlib
import sys
import time

import zenoh
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

MSG_DIR = pathlib.Path(__file__).resolve().parents[2] / "msg"


def typestore():
    """ROS 2 Humble's types plus polymap_msgs from msg/*.msg."""
    store = get_typestore(Stores.ROS2_HUMBLE)
    types = {}
    for path in sorted(MSG_DIR.glob("*.msg")):
        types.update(get_types_from_msg(path.read_text(), f"polymap_msgs/msg/{path.stem}"))
    store.register(types)
    return store


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--connect", default="tcp/127.0.0.1:7447")
    ap.add_argument("--prefix", default="polymap/leju")
    ap.add_argument("--timeout", type=float, default=20.0)
    args = ap.parse_args()

    store = typestore()
    conf = zenoh.Config.from_json5(json.dumps({
        "mode": "peer",
        "connect": {"endpoints": [args.connect]},
        "listen": {"endpoints": ["tcp/127.0.0.1:0"]},
        "scouting": {"multicast": {"enabled": False}},
    }))
    out = {}
    with zenoh.open(conf) as session:
        markers = session.declare_subscriber(f"{args.prefix}/markers")
        deadline = time.time() + args.timeout
        while "map" not in out and time.time() < deadline:
            for reply in session.get(f"{args.prefix}/map", timeout=2.0):
                if reply.ok is not None:
                    m = store.deserialize_cdr(reply.ok.payload.to_bytes(), "polymap_msgs/msg/Map")
                    out["map"] = {
                        "drift_z": m.drift_z,
                        "polygons": [
                            {
                                "id": int(p.id),
                                "label": p.label,
                                "step": int(p.step),
                                "area": p.area,
                                "centroid": [p.centroid.x, p.centroid.y, p.centroid.z],
                                "vertices": len(p.boundary),
                                "convex_pieces": len(p.convex_pieces),
                            }
                            for p in m.polygons
                        ],
                    }
            if "map" not in out:
                time.sleep(0.5)
        while "markers" not in out and time.time() < deadline:
            sample = markers.try_recv()
            if sample is None:
                time.sleep(0.05)
                continue
            a = store.deserialize_cdr(sample.payload.to_bytes(), "visualization_msgs/msg/MarkerArray")
            if a.markers:
                k = a.markers[0]
                out["markers"] = {
                    "count": len(a.markers),
                    "ns": k.ns,
                    "id": int(k.id),
                    "type": int(k.type),
                    "points": len(k.points),
                    "frame_id": k.header.frame_id,
                }
    print(json.dumps(out))
    return 0 if "map" in out and "markers" in out else 1


if __name__ == "__main__":
    sys.exit(main())
