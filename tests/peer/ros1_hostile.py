#!/usr/bin/env python3
"""Hostile ROS 1 peers against a running polymap node (tests/ros1.rs), on raw sockets, Python's
own XML-RPC and rospy: nothing here shares code with polymap. Each attack is followed by a
check that polymap still serves (its slave API answers, get_map answers) and by its resident
memory (/proc/PID/status). Prints one JSON object with what it saw.

Attacks: one plausible odometry pose 9 km away stamped ahead; a publisherUpdate naming 15,000
publishers; 300 service connections that send a header and then nothing; one that claims a
1 MiB request; a fake publisher whose 32 URIs each stall a 1 MiB message; 200 XML-RPC calls
with 1 MiB bodies at once.
"""

import argparse
import json
import os
import socket
import struct
import sys
import threading
import time
import xmlrpc.client
from xmlrpc.server import SimpleXMLRPCRequestHandler, SimpleXMLRPCServer

import rospy
from geometry_msgs.msg import Point, Pose, PoseWithCovariance, Quaternion
from nav_msgs.msg import Odometry
from polymap_msgs.srv import GetMap

ODOMETRY = "/vins_estimator/odometry"
ME = "/ros1_hostile"


def rss_mib(pid):
    with open(f"/proc/{pid}/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    return None


def wait_until(what, ok, seconds=30.0):
    """Waits for `ok()` (a bound that fails only on a hang)."""
    deadline = time.time() + seconds
    while time.time() < deadline:
        if ok():
            return True
        time.sleep(0.1)
    raise SystemExit(f"gave up waiting for {what}")


def header(fields):
    body = b"".join(struct.pack("<I", len(f)) + f for f in (f"{k}={v}".encode() for k, v in fields.items()))
    return struct.pack("<I", len(body)) + body


def read_exact(sock, n):
    out = b""
    while len(out) < n:
        chunk = sock.recv(n - len(out))
        if not chunk:
            return None
        out += chunk
    return out


def closed_within(sock, seconds):
    """Whether the peer closes `sock` within `seconds` (reading and dropping what it sends)."""
    sock.settimeout(0.5)
    deadline = time.time() + seconds
    while time.time() < deadline:
        try:
            if sock.recv(65536) == b"":
                return True
        except socket.timeout:
            continue
        except OSError:
            return True
    return False


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--pid", type=int, required=True)
    args = ap.parse_args()
    master = xmlrpc.client.ServerProxy(os.environ["ROS_MASTER_URI"])
    rospy.init_node(ME.lstrip("/"), disable_signals=True)
    api = master.lookupNode(ME, "/polymap")[2]
    slave = xmlrpc.client.ServerProxy(api)
    service_uri = master.lookupService(ME, "/polymap/get_map")[2]
    host, port = service_uri[len("rosrpc://"):].rsplit(":", 1)
    tcpros = (host, int(port))
    get_map = rospy.ServiceProxy("/polymap/get_map", GetMap)

    def serving():
        return slave.getPid(ME)[0] == 1 and get_map().map.header.frame_id != ""

    out = {"steps": {}}

    def step(name, **facts):
        facts.update(serving=serving(), rss_mib=rss_mib(args.pid))
        out["steps"][name] = facts
        print(f"{name}: {facts}", file=sys.stderr, flush=True)

    wait_until("a map", lambda: len(get_map().map.polygons) >= 5)
    step("baseline", polygons=len(get_map().map.polygons))

    # One plausible pose 9 km away, 0.4 s ahead, from a publisher polymap connects to.
    put = rospy.Publisher(ODOMETRY, Odometry, queue_size=10)
    wait_until("polymap subscribing", lambda: put.get_num_connections() >= 1)
    my_uri = rospy.get_node_uri()
    m = Odometry()
    stamp = time.time_ns() + 400_000_000
    m.header.stamp = rospy.Time(stamp // 1_000_000_000, stamp % 1_000_000_000)
    m.header.frame_id, m.child_frame_id = "world", "body"
    m.pose = PoseWithCovariance(pose=Pose(position=Point(9000.0, 0.0, 1.0), orientation=Quaternion(0, 0, 0, 1)))
    put.publish(m)
    time.sleep(2.0)
    step("phantom_pose", polygons=len(get_map().map.polygons))

    # A publisherUpdate naming 15,000 publishers (under the 1 MiB body limit), then the real list.
    uris = [f"http://127.0.0.1:1/p{i}" for i in range(15000)]
    slave.publisherUpdate("/master", ODOMETRY, uris)
    time.sleep(3.0)
    inbound = [c for c in slave.getBusInfo(ME)[2] if c[2] == "i" and c[4] == ODOMETRY]
    step("publisher_flood", inbound=len(inbound))
    slave.publisherUpdate("/master", ODOMETRY, [my_uri])
    time.sleep(2.0)
    step("publisher_flood_restored")

    # 300 service connections: a header each, then nothing. polymap still serves meanwhile,
    # and closes each once its request is overdue.
    idle = []
    for _ in range(300):
        s = socket.create_connection(tcpros)
        s.sendall(header({"callerid": ME, "service": "/polymap/get_map", "md5sum": "*"}))
        idle.append(s)
    step("idle_services_held")
    deadline = time.time() + 20.0
    closed = sum(closed_within(s, max(0.1, deadline - time.time())) for s in idle)
    for s in idle:
        s.close()
    # One that claims a 1 MiB request: refused at once.
    big = socket.create_connection(tcpros)
    big.sendall(header({"callerid": ME, "service": "/polymap/get_map", "md5sum": "*"}) + struct.pack("<I", 1 << 20) + b"x" * 1000)
    step("idle_services", closed=closed, big_request_closed=closed_within(big, 15.0))
    big.close()

    # A fake publisher: its XML-RPC answers requestTopic at any path with its TCPROS port,
    # which answers the header, then sends 1 MiB's length and 1,000 bytes, and stalls.
    stall = socket.socket()
    stall.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    stall.bind(("127.0.0.1", 0))
    stall.listen(64)
    counts = {"open": 0, "most_open": 0, "connections": 0, "held_s": []}
    lock = threading.Lock()

    def serve_stall():
        while True:
            try:
                conn, _ = stall.accept()
            except OSError:
                return
            threading.Thread(target=stalled, args=(conn,), daemon=True).start()

    def stalled(conn):
        with lock:
            counts["open"] += 1
            counts["connections"] += 1
            counts["most_open"] = max(counts["most_open"], counts["open"])
        start = time.time()
        try:
            n = struct.unpack("<I", read_exact(conn, 4))[0]
            read_exact(conn, n)
            conn.sendall(header({"callerid": "/fake", "md5sum": Odometry._md5sum, "type": Odometry._type}))
            conn.sendall(struct.pack("<I", 1 << 20) + b"\0" * 1000)
            closed_within(conn, 30.0)
        except (OSError, TypeError):
            pass
        with lock:
            counts["open"] -= 1
            counts["held_s"].append(time.time() - start)
        conn.close()

    class AnyPath(SimpleXMLRPCRequestHandler):
        rpc_paths = ()

        def log_message(self, *a):
            pass

    fake = SimpleXMLRPCServer(("127.0.0.1", 0), requestHandler=AnyPath, logRequests=False, allow_none=True)
    fake.register_function(lambda caller, topic, protocols: [1, "", ["TCPROS", "127.0.0.1", stall.getsockname()[1]]],
                           "requestTopic")
    threading.Thread(target=fake.serve_forever, daemon=True).start()
    threading.Thread(target=serve_stall, daemon=True).start()
    fakes = [f"http://127.0.0.1:{fake.server_address[1]}/p{i}" for i in range(32)]
    slave.publisherUpdate("/master", ODOMETRY, fakes + [my_uri])
    time.sleep(12.0)
    with lock:
        seen = dict(counts, held_s=sorted(counts["held_s"]))
    step("stalling_publisher", **seen)
    slave.publisherUpdate("/master", ODOMETRY, [my_uri])
    fake.shutdown()
    stall.close()

    # 200 XML-RPC calls at once, each with a 1 MiB body, then a few seconds' rest.
    def big_call():
        try:
            s = socket.create_connection((api[len("http://"):].split("/")[0].rsplit(":", 1)[0],
                                          int(api.rstrip("/").rsplit(":", 1)[1])))
            s.sendall(b"POST /RPC2 HTTP/1.1\r\nContent-Type: text/xml\r\nContent-Length: 1048576\r\n\r\n")
            chunk = b"<" * 65536
            for _ in range(16):
                s.sendall(chunk)
            closed_within(s, 10.0)
            s.close()
        except OSError:
            pass

    threads = [threading.Thread(target=big_call) for _ in range(200)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    step("xmlrpc_bodies_sent")
    time.sleep(4.0)
    step("xmlrpc_bodies")

    print(json.dumps(out))
    rospy.signal_shutdown("done")


if __name__ == "__main__":
    main()
