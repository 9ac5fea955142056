#!/usr/bin/env python3
"""An independent ROS 2 node for tests/ros2_peer.rs: zenoh-ros2-sdk (PyPI, ROBOTIS's rmw_zenoh
client), used only through its public API, with the message definitions of the packages that
define them (polymap_msgs/ as it is, the others copied into ros2_interfaces/, see SOURCE.md).
It shares no code with polymap, nor with examples/python/rmw_zenoh.py. Against a running
polymap (mock camera, mock D435i, no VINS) it:

- subscribes to polymap's topics and the D435i's, with the type hashes the SDK computes from
  the definitions (they are part of every key: a wrong hash receives nothing);
- waits for polymap's first status (its readiness); then a second node, in a process of its
  own, is polymap's VINS: odometry on /odometry, each pose of the sequence stamped when the
  mock camera shows that frame (vins_schedule.py);
- once the map is out (its markers go with it), joins /polymap/leju/map late, transient local,
  and counts what the SDK's late-joiner query brings before the subscriber is even returned;
- reads the ROS graph with the SDK's discovery (polymap's liveliness tokens);
- calls get_map and get_foothold.

Prints the SDK's type hashes on stderr and one JSON object of what it saw on stdout.
"""

import argparse
import json
import multiprocessing
import os
import pathlib
import re
import shutil
import sys
import tempfile
import threading
import time

HERE = pathlib.Path(__file__).resolve().parent
ROOT = HERE.parents[1]
sys.path.insert(0, str(HERE))

# The SDK's own session config (rmw_zenoh's default) and nothing from the environment.
for var in ("ZENOH_SESSION_CONFIG_URI", "ZENOH_CONFIG_OVERRIDE", "ROS_DOMAIN_ID"):
    os.environ.pop(var, None)

import numpy as np  # noqa: E402
import zenoh_ros2_sdk  # noqa: E402
from zenoh_ros2_sdk import (  # noqa: E402
    ROS2Publisher, ROS2ServiceClient, ROS2Subscriber, ZenohSession, get_message_class, get_registry,
    get_service_info, get_topic_info,
)
from zenoh_ros2_sdk.utils import mangle_name  # noqa: E402
from vins_schedule import Schedule  # noqa: E402

NS = "/polymap/leju"
TERRAIN = "/convex_plane_decomposition_ros/planar_terrain"
MAP = f"{NS}/map"
TOPICS = {
    f"{NS}/frame_polygons": "polymap_msgs/msg/FramePolygons",
    f"{NS}/map_updates": "polymap_msgs/msg/MapUpdate",
    f"{NS}/markers": "visualization_msgs/msg/MarkerArray",
    f"{NS}/status": "polymap_msgs/msg/Status",
    MAP: "polymap_msgs/msg/Map",
    "/tf": "tf2_msgs/msg/TFMessage",
    TERRAIN: "convex_plane_decomposition_msgs/msg/PlanarTerrain",
    "/camera/camera/infra1/image_rect_raw": "sensor_msgs/msg/Image",
    "/camera/camera/infra1/camera_info": "sensor_msgs/msg/CameraInfo",
    "/camera/camera/imu": "sensor_msgs/msg/Imu",
}
SERVICES = {f"{NS}/get_map": "polymap_msgs/srv/GetMap", f"{NS}/get_foothold": "polymap_msgs/srv/GetFoothold"}
# Latched topics (reliable, transient local, keep last 1), in rmw_zenoh's QoS token form.
LATCHED_QOS = ":1:,1:,:,:,,"
LATCHED = {MAP, f"{NS}/markers", TERRAIN}
# VINS's odometry: reliable, keep last 100.
ODOMETRY_QOS = "::,100:,:,:,,"
NODE = "ros2_sdk_peer"
DOMAIN = 0


def messages_dir():
    """The one directory the SDK's registry reads (<pkg>/msg/<Name>.msg, <pkg>/srv/<Name>.srv):
    links to polymap_msgs/ and to each package in ros2_interfaces/, so that nothing is copied
    and the SDK never needs its download from GitHub."""
    d = pathlib.Path(tempfile.mkdtemp(prefix="ros2_sdk_peer_"))
    (d / "polymap_msgs").symlink_to(ROOT / "polymap_msgs")
    for pkg in sorted((HERE / "ros2_interfaces").iterdir()):
        if pkg.is_dir():
            (d / pkg.name).symlink_to(pkg)
    return d


class TransientLocalSubscriber(ROS2Subscriber):
    """Works around a bug of zenoh-ros2-sdk 0.1.8: to find the publishers whose caches a
    transient-local subscriber asks for history, ROS2Subscriber._discover_publishers matches
    liveliness tokens on `%{topic.lstrip('/')}`, mangling only the leading '/', where rmw_zenoh
    writes every '/' of the name as '%' (`%polymap%leju%map`). It finds no publisher of any
    name with more than one token, and the late joiner gets no history. The same query, with
    the name mangled as rmw_zenoh (and the SDK's own keyexpr.py) does."""

    def _discover_publishers(self):
        pattern = (f"@ros2_lv/{self.domain_id}/*/*/*/MP/*/*/*/{mangle_name(self.topic)}/"
                   f"{self.dds_type_name}/{self.type_hash}/*")
        zids = set()
        for reply in self.session_mgr.liveliness.get(pattern, timeout=2.0):
            if reply.ok is not None:
                zids.add(str(reply.ok.key_expr).split("/")[2])
        return sorted(zids)


PRIMITIVES = {"bool", "byte", "char", "int8", "uint8", "int16", "uint16", "int32", "uint32", "int64", "uint64",
              "float32", "float64", "string", "wstring"}


def service_definitions(srv_type):
    """The request's and the response's definitions from the package's .srv file, with the
    package named in each reference to one of its own messages (`Map map` becomes
    `polymap_msgs/Map map`), which means the same type and gives the same hash.

    Works around a bug of zenoh-ros2-sdk 0.1.8: it parses a service's request and response
    with rosbags under the names `<pkg>/srv/<Name>_Request` and `_Response`, so rosbags
    resolves a field typed by a bare message name of the same package (`Map`, as ROS 2 .srv
    files write them) to `<pkg>/srv/msg/Map`, a type that does not exist: the call is sent, and
    every reply fails to decode (KeyError: 'polymap_msgs/srv/msg/Map')."""
    pkg, _, name = srv_type.split("/")
    text = (ROOT / pkg / "srv" / f"{name}.srv").read_text()
    parts = []
    for part in text.split("\n---\n"):
        lines = []
        for line in part.splitlines():
            words = line.split("#", 1)[0].split()
            if len(words) >= 2 and re.split(r"[\[<]", words[0])[0] not in PRIMITIVES and "/" not in words[0]:
                line = line.replace(words[0], f"{pkg}/{words[0]}", 1)
            lines.append(line)
        parts.append("\n".join(lines) + "\n")
    request, response = parts
    return {"request_definition": request, "response_definition": response}


class Stream:
    """What arrived on one topic."""

    def __init__(self):
        self.count, self.first, self.last = 0, None, None
        self.all = []  # kept only where the whole history is checked

    def take(self, msg, keep_all):
        self.count += 1
        self.last = msg
        if self.first is None:
            self.first = msg
        if keep_all:
            self.all.append(msg)


def status_facts(s):
    return None if s is None else {
        "processed": int(s.frames_processed), "without_pose": int(s.frames_without_pose),
        "poses_accepted": int(s.poses_accepted), "poses_refused": int(s.poses_refused)}


def endpoint_facts(e, typename):
    return {"node": e.node_name, "namespace": e.node_namespace, "type": typename, "hash": e.type_hash, "qos": e.qos}


def vins(host, port, definitions, sequence, stop, said, parent, deadline):
    """The VINS node: odometry on /odometry, each pose of the sequence stamped when the mock
    camera shows that frame, until told to stop (or its parent is gone). Says its type hash,
    how many it sent, and when it was held up for more than 0.1 s ([when, how long], s after
    its start), which a loaded machine does: the poses due meanwhile go out late, as a VINS
    that was held up sends them (the schedule's window is 1 s, not its 0.1 s), so that only a
    hold-up longer than polymap waits for a pose (poses.max_wait_s, 0.3 s) costs frames theirs."""
    ZenohSession.get_instance(host, port)
    get_registry(definitions)
    odometry = ROS2Publisher("/odometry", "nav_msgs/msg/Odometry", node_name="ros2_sdk_vins", qos=ODOMETRY_QOS,
                             router_ip=host, router_port=port, domain_id=DOMAIN)
    T = {n: get_message_class(f"{p}/msg/{n}") for p, n in [
        ("builtin_interfaces", "Time"), ("std_msgs", "Header"), ("geometry_msgs", "Point"),
        ("geometry_msgs", "Quaternion"), ("geometry_msgs", "Pose"), ("geometry_msgs", "PoseWithCovariance"),
        ("geometry_msgs", "Vector3"), ("geometry_msgs", "Twist"), ("geometry_msgs", "TwistWithCovariance")]}
    zero = T["Vector3"](x=0.0, y=0.0, z=0.0)
    twist = T["TwistWithCovariance"](twist=T["Twist"](linear=zero, angular=zero), covariance=np.zeros(36))
    schedule = Schedule(pathlib.Path(sequence))
    published, stalls = 0, []
    start = before = time.time()
    while not stop.is_set() and os.getppid() == parent and time.time() - start < deadline:
        now = time.time()
        if now - before > 0.1:
            stalls.append((round(now - start, 2), round(now - before, 3)))
        before = now
        for stamp, p, q in schedule.due(time.time_ns(), window_ns=1_000_000_000):
            odometry.publish(
                header=T["Header"](stamp=T["Time"](sec=stamp // 1_000_000_000, nanosec=stamp % 1_000_000_000),
                                   frame_id="world"),
                child_frame_id="body",
                pose=T["PoseWithCovariance"](
                    pose=T["Pose"](position=T["Point"](x=p[0], y=p[1], z=p[2]),
                                   orientation=T["Quaternion"](x=q[0], y=q[1], z=q[2], w=q[3])),
                    covariance=np.zeros(36)),
                twist=twist)
            published += 1
        time.sleep(0.003)
    said.put({"type_hash": odometry.type_hash, "published": published, "stalls": stalls})
    ZenohSession.get_instance().close()


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--connect", required=True, help="tcp/<ip>:<port> of polymap's Zenoh")
    ap.add_argument("--sequence", required=True, type=pathlib.Path)
    ap.add_argument("--seconds", type=float, default=12.0, help="how long it is polymap's VINS")
    ap.add_argument("--deadline", type=float, default=120.0, help="gives up after this many seconds")
    args = ap.parse_args()

    # Whatever happens to polymap, the test gets an answer.
    def give_up():
        print(f"ros2_sdk_peer: no result within {args.deadline} s", file=sys.stderr, flush=True)
        os._exit(3)
    watchdog = threading.Timer(args.deadline, give_up)
    watchdog.daemon = True
    watchdog.start()

    proto, _, where = args.connect.partition("/")
    host, _, port = where.rpartition(":")
    assert proto == "tcp", args.connect
    # The session first (the SDK keeps one, made by the first call that wants it), then the
    # registry on the local definitions, before anything else asks for either.
    ZenohSession.get_instance(host, int(port))
    definitions = messages_dir()
    get_registry(str(definitions))
    where = {"router_ip": host, "router_port": int(port), "domain_id": DOMAIN}

    streams = {name: Stream() for name in TOPICS}
    lock = threading.Lock()
    arrived = threading.Condition(lock)

    def taker(name):
        keep_all = name.endswith("/map_updates")

        def take(msg):
            with lock:
                streams[name].take(msg, keep_all)
                arrived.notify_all()
        return take

    subs = {}
    for name, typename in TOPICS.items():
        if name == MAP:
            continue  # joined late, below
        cls = TransientLocalSubscriber if name in LATCHED else ROS2Subscriber
        subs[name] = cls(name, typename, taker(name), node_name=NODE, qos=LATCHED_QOS if name in LATCHED else None, **where)
    # The messages the answers hold, from the registry (the SDK registers only what the
    # definitions it is given say, not what they refer to).
    for ty in ("polymap_msgs/msg/Map", "polymap_msgs/msg/Foothold"):
        get_message_class(ty)
    clients = {name: ROS2ServiceClient(name, srv, node_name=NODE, timeout=10.0, **service_definitions(srv), **where)
               for name, srv in SERVICES.items()}

    Point = get_message_class("geometry_msgs/msg/Point")

    # Readiness: polymap's first status (every second, odometry or not) says its publishers
    # and this node's subscriptions have met.
    status = streams[f"{NS}/status"]
    with lock:
        if not arrived.wait_for(lambda: status.count > 0, timeout=60.0):
            print("ros2_sdk_peer: no status from polymap within 60 s", file=sys.stderr, flush=True)
            os._exit(2)

    # From now on a second node, in a process of its own, is polymap's VINS, whatever this one
    # does (a Python process that also decodes ten topics holds its odometry up for longer).
    spawn = multiprocessing.get_context("spawn")
    stop, vins_said = spawn.Event(), spawn.Queue()
    vins_node = spawn.Process(target=vins, args=(host, int(port), str(definitions), str(args.sequence), stop, vins_said,
                                                 os.getpid(), args.deadline))
    vins_node.start()
    start = time.time()

    def wait_for(what, ready, timeout=30.0):
        with lock:
            if not arrived.wait_for(ready, timeout=timeout):
                print(f"ros2_sdk_peer: {what} not within {timeout} s", file=sys.stderr, flush=True)
                os._exit(2)
            return status.last

    # The status counts taken as "early": two statuses after the first that shows the VINS's
    # poses accepted, when the frames shot before the odometry flowed are all counted.
    wait_for("poses accepted", lambda: status.last.poses_accepted > 0)
    accepted_at = status.count
    status_early = wait_for("two more statuses", lambda: status.count >= accepted_at + 2)

    # The late joiner, once the map is out (its markers go with it): what the SDK's
    # history query brings arrives before the constructor returns.
    wait_for("the markers", lambda: streams[f"{NS}/markers"].count > 0)
    joined = time.time() - start
    subs[MAP] = TransientLocalSubscriber(MAP, TOPICS[MAP], taker(MAP), node_name=NODE, qos=LATCHED_QOS, **where)
    with lock:
        late = {"after_s": round(joined, 1), "at_join": streams[MAP].count,
                "first": None if streams[MAP].first is None else map_facts(streams[MAP].first)}

    time.sleep(max(0.0, args.seconds - (time.time() - start)))

    # The graph, as the SDK's discovery reads polymap's liveliness tokens.
    graph = {}
    for name in list(TOPICS) + ["/odometry"]:
        info = get_topic_info(name, verbose=True, timeout=1.0, **where)
        graph[name] = None if info is None else {
            "publishers": [endpoint_facts(e, e.topic_type) for e in info.publishers],
            "subscribers": [endpoint_facts(e, e.topic_type) for e in info.subscribers]}
    for name in SERVICES:
        info = get_service_info(name, verbose=True, timeout=1.0, **where)
        graph[name] = None if info is None else {
            "servers": [endpoint_facts(e, e.service_type) for e in info.servers],
            "clients": [endpoint_facts(e, e.service_type) for e in info.clients]}

    response = clients[f"{NS}/get_map"].call(structure_needs_at_least_one_member=0)
    f_response = clients[f"{NS}/get_foothold"].call(point=Point(x=0.42, y=0.0, z=0.30))

    hashes = {s.msg_type: s.type_hash for s in subs.values()}
    hashes.update({c.srv_type: c.type_hash for c in clients.values()})

    # The last status while the odometry flowed (once it stops, the frames still waiting for
    # a pose are counted without one), then the odometry stops.
    with lock:
        status_last = status.last
    stop.set()
    odometry = vins_said.get(timeout=30.0)
    vins_node.join(timeout=30.0)
    hashes["nav_msgs/msg/Odometry"] = odometry["type_hash"]
    for t, h in sorted(hashes.items()):
        print(f"zenoh-ros2-sdk {zenoh_ros2_sdk.__version__}: {t} {h}", file=sys.stderr)

    with lock:
        s = {n: streams[n] for n in TOPICS}
        updates = s[f"{NS}/map_updates"].all
        out = {
            "sdk": zenoh_ros2_sdk.__version__,
            "odometry_published": odometry["published"],
            "odometry_stalls": odometry["stalls"],
            "counts": {n: st.count for n, st in s.items()},
            "hashes": hashes,
            "graph": graph,
            "late_map": late,
            "map_last": None if s[MAP].last is None else map_facts(s[MAP].last),
            # map_updates is keep-all: each update starts from the version the previous made.
            "map_updates": {"count": len(updates), "breaks": sum(
                1 for a, b in zip(updates, updates[1:]) if b.epoch == a.epoch and b.from_version != a.version),
                "last_version": int(updates[-1].version) if updates else None},
            "frame_polygons_first": first_of(s[f"{NS}/frame_polygons"], lambda m: {
                "frame_id": m.header.frame_id, "polygons": len(m.polygons)}),
            "markers_last": first_of(s[f"{NS}/markers"], lambda m: {"markers": len(m.markers)}, last=True),
            "terrain_first": first_of(s[TERRAIN], lambda m: {
                "frame_id": m.gridmap.header.frame_id, "layers": list(m.gridmap.layers),
                "regions": len(m.planar_regions), "resolution": float(m.gridmap.info.resolution)}),
            "tf_last": first_of(s["/tf"], lambda m: {
                "parent": m.transforms[0].header.frame_id, "child": m.transforms[0].child_frame_id}, last=True),
            "image_first": first_of(s["/camera/camera/infra1/image_rect_raw"], lambda m: {
                "width": int(m.width), "height": int(m.height), "encoding": m.encoding, "bytes": len(m.data)}),
            "camera_info_first": first_of(s["/camera/camera/infra1/camera_info"], lambda m: {
                "width": int(m.width), "height": int(m.height), "frame_id": m.header.frame_id}),
            "imu_first": first_of(s["/camera/camera/imu"], lambda m: {
                "angular_velocity_covariance": [float(v) for v in m.angular_velocity_covariance],
                "frame_id": m.header.frame_id}),
            "status_early": status_facts(status_early),
            "status_last": status_facts(status_last),
            "map": None if response is None else {
                "frame_id": response.map.header.frame_id, "polygons": len(response.map.polygons),
                "treads": sum(1 for p in response.map.polygons if int(p.label) == 2),
                # label, centroid, for the failure messages
                "polygons_seen": [[int(p.label)] + [round(float(c), 2) for c in (p.centroid.x, p.centroid.y, p.centroid.z)]
                                  for p in response.map.polygons]},
            "foothold": None if f_response is None else {
                "found": bool(f_response.foothold.found), "contains": bool(f_response.foothold.contains),
                "label": int(f_response.foothold.label)},
            "foothold_where": None if f_response is None else {
                "polygon_id": int(f_response.foothold.polygon_id), "offset": float(f_response.foothold.offset),
                "normal": [float(v) for v in f_response.foothold.normal]},
        }
    print(json.dumps(out))
    sys.stdout.flush()
    shutil.rmtree(definitions, ignore_errors=True)
    ZenohSession.get_instance().close()


def map_facts(m):
    return {"frame_id": m.header.frame_id, "epoch": int(m.epoch), "version": int(m.version), "polygons": len(m.polygons)}


def first_of(stream, facts, last=False):
    msg = stream.last if last else stream.first
    return None if msg is None else facts(msg)


if __name__ == "__main__":
    main()
