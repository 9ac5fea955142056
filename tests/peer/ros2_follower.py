#!/usr/bin/env python3
"""A planner's copy of polymap's map, kept as README.md's "The planner contract" says, on
ROS 2: a node on rmw_zenoh made with zenoh-ros2-sdk (robotis-git/zenoh_ros2_sdk, an rmw_zenoh
client on eclipse-zenoh and rosbags that shares no code with polymap), its messages from
polymap_msgs/msg/*.msg and srv/*.srv and the ROS 2 packages' own .msg files
(tests/peer/ros2_interfaces). The copy and its rules are tests/peer/ros1_follower.py's
(MapCopy, Driver: the README's contract, ROS-neutral); the commands on stdin and the JSON
lines on stdout are the same.

It subscribes to `map_updates` (reliable, keep all) and the transient-local `map` (the SDK
asks the publishers' caches for the latest when it subscribes), then asks `get_map`.
"""

import argparse
import os
import pathlib
import sys
import tempfile

HERE = pathlib.Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from ros1_follower import Driver, MapCopy  # noqa: E402

# ROS 2 Jazzy's definitions of the standard types polymap_msgs uses, for a checkout without
# tests/peer/ros2_interfaces.
JAZZY = {
    "builtin_interfaces/msg/Time.msg": "int32 sec\nuint32 nanosec\n",
    "std_msgs/msg/Header.msg": "builtin_interfaces/Time stamp\nstring frame_id\n",
    "geometry_msgs/msg/Point.msg": "float64 x\nfloat64 y\nfloat64 z\n",
}


def messages_dir():
    """The SDK's message registry: polymap_msgs as the repository has it, the standard
    packages as upstream's .msg files."""
    out = pathlib.Path(tempfile.mkdtemp(prefix="ros2_follower_msgs_"))
    (out / "polymap_msgs").symlink_to(HERE.parents[1] / "polymap_msgs")
    interfaces = HERE / "ros2_interfaces"
    for rel, text in JAZZY.items():
        package = rel.split("/")[0]
        if (interfaces / rel).exists():
            if not (out / package).exists():
                (out / package).symlink_to(interfaces / package)
        else:
            path = out / rel
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(text)
    return out


PRIMITIVES = {"bool", "byte", "char", "float32", "float64", "int8", "uint8", "int16", "uint16", "int32", "uint32",
              "int64", "uint64", "string", "wstring"}


def qualified(text, package):
    """A .srv part with its own package's messages named in full (`Map map` ->
    `polymap_msgs/Map map`): zenoh-ros2-sdk 0.1.8 parses a service's parts as messages of
    `<package>/srv/`, where a bare name would resolve to `<package>/srv/msg/<Name>`."""
    out = []
    for line in text.splitlines():
        words = line.split()
        if words and not words[0].startswith("#") and "/" not in words[0] and words[0].split("[")[0] not in PRIMITIVES:
            line = line.replace(words[0], f"{package}/{words[0]}", 1)
        out.append(line)
    return "\n".join(out)


def transient_local(subscriber, driver):
    """The latest whole map from the publishers' caches, as rmw_zenoh's transient-local
    subscriptions ask zenoh-ext's advanced publishers for it (`<key>/@adv/**`). The SDK asks
    only publishers it finds by a liveliness pattern that leaves the '/' inside a topic's
    name unmangled (0.1.8: `%polymap/leju/map` for `%polymap%leju%map`), so it finds none for
    a namespaced topic: asked here."""
    session, store = subscriber.session_mgr.session, subscriber.session_mgr.store
    for reply in session.get(f"{subscriber.keyexpr}/@adv/**?_anyke;_max=1", timeout=3.0):
        if reply.ok is not None:
            driver.whole_map(store.deserialize_cdr(reply.ok.payload.to_bytes(), "polymap_msgs/msg/Map"))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--port", type=int, required=True, help="the mapper's Zenoh port on 127.0.0.1")
    ap.add_argument("--name", default="ros2_follower")
    ap.add_argument("--namespace", default="/polymap/leju")
    ap.add_argument("--drop-every", type=int, default=0, help="lose every n-th update received (0: none)")
    args = ap.parse_args()

    # The registry is the SDK's singleton: given its directory before anything asks it.
    from zenoh_ros2_sdk.message_registry import get_registry
    get_registry(str(messages_dir()))
    from zenoh_ros2_sdk import ROS2ServiceClient, ROS2Subscriber
    from zenoh_ros2_sdk.qos import QosDurability, QosHistoryKind, QosProfile

    endpoint = {"router_ip": "127.0.0.1", "router_port": args.port, "node_name": args.name}
    copy = MapCopy(args.drop_every)
    request, response = (HERE.parents[1] / "polymap_msgs/srv/GetMap.srv").read_text().split("\n---\n")
    client = ROS2ServiceClient(f"{args.namespace}/get_map", "polymap_msgs/srv/GetMap", timeout=5.0,
                               request_definition=qualified(request, "polymap_msgs"),
                               response_definition=qualified(response, "polymap_msgs"), **endpoint)

    def fetch():
        answer = client.call(structure_needs_at_least_one_member=0)
        if answer is None:
            raise TimeoutError("get_map: no answer")
        return answer.map

    driver = Driver(copy, fetch)
    # Subscribe first, then ask (the driver asks at once: no map is held).
    updates = ROS2Subscriber(topic=f"{args.namespace}/map_updates", msg_type="polymap_msgs/msg/MapUpdate",
                             callback=driver.update, qos=QosProfile(history_kind=QosHistoryKind.KEEP_ALL), **endpoint)
    whole = ROS2Subscriber(topic=f"{args.namespace}/map", msg_type="polymap_msgs/msg/Map", callback=driver.whole_map,
                           qos=QosProfile(durability=QosDurability.TRANSIENT_LOCAL, history_depth=1), **endpoint)
    transient_local(whole, driver)
    driver.run()
    sys.stdout.flush()
    del updates, whole
    # Zenoh's threads may hold the interpreter's exit; the answers are out.
    os._exit(0)


if __name__ == "__main__":
    main()
