#!/usr/bin/env python3
"""A planner's copy of polymap's map, kept as README.md's "The planner contract" says, on
ROS 1: a rospy node (Debian's ros_comm, Noetic's) with polymap_msgs as genpy generates
them from polymap's own package. It shares no code with polymap: the rules below are the
README's and the message definitions' (polymap_msgs/msg/MapUpdate.msg, Map.msg), written
out again here, not a port of polymap::interface::follower.

The contract, as this copy keeps it:
- subscribe to `map_updates` and to the whole `map` (latched on ROS 1), then ask `get_map`;
- hold (epoch, version): an update of the held epoch from the held version is applied
  (added and changed polygons replace whole ones by id, removed ids go); one at or below the
  held version, or of an older epoch, is ignored; one past the held version, or of a newer
  epoch (a restarted mapper), is kept and a whole map is asked for;
- a whole map newer than the one held is taken, then the kept updates that follow from it;
  one not newer is ignored.

Driven by the test on stdin, one command a line; answers on stdout, one JSON object a line:
- at start, once it holds a map and get_map answered: {"ready": ...};
- `check LABEL`: waits for the map to stop changing (get_map asked every 1.5 s until two
  answers agree), waits for the copy to reach that version, and compares the copy with that
  answer polygon by polygon, every field the message carries: {"check": LABEL, "equal": ...};
  the answers it compares with are never put into the copy;
- `quit` (or the end of stdin): {"bye": ...}, and exits.

The contract's logic (MapCopy, Driver) is ROS-neutral: tests/peer/ros2_follower.py keeps
its copy with it on ROS 2. rospy is imported only by this file's main.
"""

import argparse
import dataclasses
import json
import math
import queue
import sys
import threading
import time

# Updates kept while a whole map is awaited; the oldest go first (the whole map covers them).
MAX_KEPT = 4096
# How long a check waits for the map to settle, and then for the copy to reach it. Bounds
# on a hang only: the map settles seconds after the odometry stops and the whole map is
# republished within a second of any change.
SETTLE_LIMIT_S = 180.0
CATCH_UP_LIMIT_S = 60.0
SETTLE_POLL_S = 1.5


def plain(x):
    """A message value as plain Python (dicts, lists, numbers, strings), from genpy's classes
    (ROS 1) or rosbags' dataclasses and numpy arrays (ROS 2) alike."""
    if x is None or isinstance(x, (bool, int, float, str)):
        return x
    if isinstance(x, (bytes, bytearray)):
        return list(x)
    if hasattr(x, "tolist"):  # numpy arrays and scalars
        return plain(x.tolist())
    if isinstance(x, (list, tuple)):
        return [plain(v) for v in x]
    if hasattr(x, "_slot_types"):  # genpy
        return {s: plain(getattr(x, s)) for s in x.__slots__}
    if dataclasses.is_dataclass(x):  # rosbags
        return {f.name: plain(getattr(x, f.name)) for f in dataclasses.fields(x) if not f.name.startswith("__")}
    raise TypeError(f"no plain form for {type(x)}")


def same(a, b):
    """Equal, exactly (bit for bit but for NaN, which equals NaN here)."""
    if isinstance(a, float) or isinstance(b, float):
        if isinstance(a, (int, float)) and isinstance(b, (int, float)):
            return a == b or (math.isnan(a) and math.isnan(b))
        return False
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(same(a[k], b[k]) for k in a)
    if isinstance(a, list) and isinstance(b, list):
        return len(a) == len(b) and all(same(x, y) for x, y in zip(a, b))
    return a == b


def update_of(u):
    """A polymap_msgs/MapUpdate, plain."""
    return {"epoch": int(u.epoch), "from_version": int(u.from_version), "version": int(u.version),
            "added": [plain(p) for p in u.added], "changed": [plain(p) for p in u.changed],
            "removed": [int(i) for i in u.removed], "drift_z": float(u.drift_z), "drift_var": float(u.drift_var),
            "frame_id": u.header.frame_id}


def map_of(m):
    """A polymap_msgs/Map, plain."""
    return {"epoch": int(m.epoch), "version": int(m.version), "polygons": [plain(p) for p in m.polygons],
            "drift_z": float(m.drift_z), "drift_var": float(m.drift_var), "frame_id": m.header.frame_id}


class MapCopy:
    """The map as the planner holds it: polygons by id, the drift, the frame, and the
    (epoch, version) it is at."""

    def __init__(self, drop_every=0):
        self.held = None
        self.polygons = {}
        self.drift = (0.0, 0.0)
        self.frame_id = ""
        self.kept = {}  # (epoch, from_version) -> update, past the map held
        self.drop_every = drop_every
        self.epochs = []  # every epoch held, in order
        self.counters = {"received": 0, "dropped": 0, "applied": 0, "stale": 0, "gaps": 0, "new_epochs": 0,
                         "kept_dropped": 0, "whole_maps_taken": 0, "whole_maps_ignored": 0}

    def needs_whole_map(self):
        return self.held is None or bool(self.kept)

    def on_update(self, u):
        """An update as it arrived (plain). With drop_every, every n-th is lost here, as a
        lossy link would lose it."""
        c = self.counters
        c["received"] += 1
        if self.drop_every and c["received"] % self.drop_every == 0:
            c["dropped"] += 1
            return
        if self.held is None:
            self._keep(u)
            return
        epoch, version = self.held
        if u["epoch"] < epoch:
            c["stale"] += 1
        elif u["epoch"] > epoch:
            c["new_epochs"] += 1
            self._keep(u)
        elif u["from_version"] == version:
            self._apply(u)
            self._follow_on()
        elif u["version"] <= version:
            c["stale"] += 1
        else:
            c["gaps"] += 1
            self._keep(u)

    def on_map(self, m):
        """A whole map (plain): taken if newer than the one held. Returns whether it was."""
        if self.held is not None and (m["epoch"], m["version"]) <= self.held:
            self.counters["whole_maps_ignored"] += 1
            return False
        self.polygons = {p["id"]: p for p in m["polygons"]}
        self.drift = (m["drift_z"], m["drift_var"])
        self.frame_id = m["frame_id"]
        self._hold((m["epoch"], m["version"]))
        self.counters["whole_maps_taken"] += 1
        self._follow_on()
        return True

    def _hold(self, at):
        if not self.epochs or self.epochs[-1] != at[0]:
            self.epochs.append(at[0])
        self.held = at

    def _keep(self, u):
        self.kept[(u["epoch"], u["from_version"])] = u
        while len(self.kept) > MAX_KEPT:
            del self.kept[min(self.kept)]
            self.counters["kept_dropped"] += 1

    def _apply(self, u):
        for i in u["removed"]:
            self.polygons.pop(i, None)
        for p in u["added"] + u["changed"]:
            self.polygons[p["id"]] = p
        self.drift = (u["drift_z"], u["drift_var"])
        self.frame_id = u["frame_id"]
        self._hold((u["epoch"], u["version"]))
        self.counters["applied"] += 1

    def _follow_on(self):
        """Applies the kept updates that start where the copy is; forgets those it passed."""
        while True:
            self.kept = {k: u for k, u in self.kept.items() if (u["epoch"], u["version"]) > self.held}
            nxt = self.kept.pop(self.held, None)
            if nxt is None:
                return
            self._apply(nxt)

    def compare(self, m):
        """The copy against a whole map (plain): what differs, polygon by polygon, field by field."""
        differences = []
        if self.held != (m["epoch"], m["version"]):
            differences.append(f"holds (epoch, version) {self.held}, the map is {(m['epoch'], m['version'])}")
        if not same(list(self.drift), [m["drift_z"], m["drift_var"]]):
            differences.append(f"drift (z, var) {self.drift}, the map's ({m['drift_z']}, {m['drift_var']})")
        if self.frame_id != m["frame_id"]:
            differences.append(f"frame {self.frame_id!r}, the map's {m['frame_id']!r}")
        theirs = {p["id"]: p for p in m["polygons"]}
        missing = sorted(set(theirs) - set(self.polygons))
        extra = sorted(set(self.polygons) - set(theirs))
        if missing:
            differences.append(f"polygons missing from the copy: {missing}")
        if extra:
            differences.append(f"polygons the map no longer has: {extra}")
        for i in sorted(set(theirs) & set(self.polygons)):
            fields = [k for k in theirs[i] if not same(self.polygons[i].get(k), theirs[i][k])]
            if fields:
                differences.append(f"polygon {i} differs in {fields}")
        return differences


class Driver:
    """Feeds a MapCopy what the subscriptions deliver (from their threads, through a queue),
    asks for a whole map when the copy needs one, and answers the test's commands."""

    def __init__(self, copy, fetch, subscribed=lambda: True, log=None):
        self.copy = copy
        self.fetch = fetch  # -> a polymap_msgs/Map (get_map's answer), or raises
        self.subscribed = subscribed
        self.events = queue.Queue()
        self.commands = queue.Queue()
        self.fetches = {"taken": 0, "not_newer": 0, "failed": 0}
        self.topic_maps = 0  # whole maps that came on the `map` topic
        self.answered = False  # get_map answered once (rule 1: asked at start whatever came)
        self.last_fetch = 0.0
        self.log = log or (lambda s: print(s, file=sys.stderr, flush=True))

    # Subscription callbacks (any thread).
    def update(self, msg):
        self.events.put(("update", msg))

    def whole_map(self, msg):
        self.events.put(("map", msg))

    def _ask(self):
        """get_map, put into the copy: the contract's way back after a gap or a restart."""
        self.last_fetch = time.monotonic()
        try:
            m = self.fetch()
        except Exception as e:  # noqa: BLE001 - the mapper may be away (restarting)
            self.fetches["failed"] += 1
            self.log(f"get_map: {e!r}")
            return
        self.answered = True
        taken = self.copy.on_map(map_of(m))
        self.fetches["taken" if taken else "not_newer"] += 1

    def pump(self, seconds):
        """Takes what arrives for `seconds`, asking for a whole map while the copy needs one."""
        deadline = time.monotonic() + seconds
        while True:
            wanted = not self.answered or self.copy.needs_whole_map()
            if wanted and time.monotonic() - self.last_fetch >= 0.25:
                self._ask()
            left = deadline - time.monotonic()
            if left <= 0:
                return
            try:
                kind, msg = self.events.get(timeout=min(left, 0.05))
            except queue.Empty:
                continue
            if kind == "update":
                self.copy.on_update(update_of(msg))
            else:
                self.topic_maps += 1
                self.copy.on_map(map_of(msg))

    def summary(self):
        c = self.copy
        return {"held": list(c.held) if c.held else None, "polygons": len(c.polygons), "epochs": c.epochs,
                "kept": len(c.kept), "counters": dict(c.counters), "fetches": dict(self.fetches),
                "topic_maps": self.topic_maps}

    def check(self, label):
        started = time.monotonic()
        settled, last = None, None
        while settled is None and time.monotonic() - started < SETTLE_LIMIT_S:
            try:
                m = map_of(self.fetch())  # compared with, never put into the copy
            except Exception as e:  # noqa: BLE001
                self.log(f"check {label}: get_map: {e!r}")
                m = None
            if m is not None:
                if last is not None and (m["epoch"], m["version"]) == (last["epoch"], last["version"]):
                    settled = m
                    break
                last = m
            self.pump(SETTLE_POLL_S)
        out = {"check": label, **self.summary()}
        if settled is None:
            out.update({"equal": False, "settled": False, "differences": ["the map did not settle"]})
            return out
        at = (settled["epoch"], settled["version"])
        caught_up = time.monotonic()
        while self.copy.held != at and time.monotonic() - caught_up < CATCH_UP_LIMIT_S:
            self.pump(0.1)
        differences = self.copy.compare(settled)
        out.update(self.summary())
        out.update({"equal": not differences, "settled": True, "epoch": at[0], "version": at[1],
                    "map_polygons": len(settled["polygons"]), "differences": differences[:40],
                    "settle_s": round(time.monotonic() - started, 2)})
        return out

    def run(self):
        """Until `quit` or the end of stdin."""
        def read():
            for line in sys.stdin:
                self.commands.put(line.strip())
            self.commands.put("quit")

        threading.Thread(target=read, daemon=True).start()
        ready = False
        while True:
            self.pump(0.1)
            if not ready and self.copy.held is not None and self.answered and self.subscribed():
                ready = True
                say({"ready": True, **self.summary()})
            try:
                command = self.commands.get_nowait()
            except queue.Empty:
                continue
            if command.startswith("check"):
                say(self.check(command.partition(" ")[2] or "check"))
            elif command == "quit":
                say({"bye": True, **self.summary()})
                return
            elif command:
                self.log(f"unknown command {command!r}")


def say(obj):
    sys.stdout.write(json.dumps(obj) + "\n")
    sys.stdout.flush()


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--name", default="ros1_follower")
    ap.add_argument("--namespace", default="/polymap")
    ap.add_argument("--drop-every", type=int, default=0, help="lose every n-th update received (0: none)")
    args = ap.parse_args()

    import rospy
    from polymap_msgs.msg import Map, MapUpdate
    from polymap_msgs.srv import GetMap

    rospy.init_node(args.name, disable_signals=True)
    get_map = rospy.ServiceProxy(f"{args.namespace}/get_map", GetMap)

    def fetch():
        return get_map().map

    copy = MapCopy(args.drop_every)
    driver = Driver(copy, fetch)
    # Subscribe first, then ask (the driver asks at once: no map is held). queue_size None:
    # rospy's own queue loses nothing.
    updates = rospy.Subscriber(f"{args.namespace}/map_updates", MapUpdate, driver.update, queue_size=None)
    whole = rospy.Subscriber(f"{args.namespace}/map", Map, driver.whole_map, queue_size=None)
    driver.subscribed = lambda: updates.get_num_connections() > 0 and whole.get_num_connections() > 0
    driver.run()
    rospy.signal_shutdown("done")


if __name__ == "__main__":
    main()
