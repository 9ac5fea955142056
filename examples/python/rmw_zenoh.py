"""A small ROS 2 peer on Zenoh, speaking rmw_zenoh's protocol from Python.

Written from rmw_zenoh's docs/design.md (Jazzy) with eclipse-zenoh for the transport and
rosbags for CDR and type hashes (REP 2016); it shares no code with polymap. polymap's
Python examples use it to reach polymap as a ROS 2 node on rmw_zenoh would, and polymap's
tests use it as the independent ROS 2 peer.

- keys: <domain>/<name without leading '/'>/<pkg>::msg::dds_::<Type>_/<RIHS01 hash>
- every sample, query and reply carries an attachment: sequence number (int64 LE), source
  timestamp (int64 LE, ns), then the 16-byte GID as a sequence (length byte 16 + bytes)
- liveliness tokens @ros2_lv/<domain>/<zid>/<node id>/<entity id>/<kind>/<enclave>/<ns>/<node>
  [/<name>/<type>/<hash>/<qos>], '/' in names written '%'
- services: queries to complete queryables (target ALL_COMPLETE), the CDR request as payload
"""

import os
import pathlib
import secrets
import struct
import time

import zenoh
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.base import Nodetype

POLYMAP_MSGS = pathlib.Path(__file__).resolve().parents[2] / "polymap_msgs"
DEFAULT_QOS = "::,10:,:,:,,"


def _load_polymap_msgs(store):
    """polymap_msgs' messages and services, from polymap_msgs/msg/*.msg and srv/*.srv."""
    types = {}
    for path in sorted((POLYMAP_MSGS / "msg").glob("*.msg")):
        types.update(get_types_from_msg(path.read_text(), f"polymap_msgs/msg/{path.stem}"))
    store.register(types)
    for path in sorted((POLYMAP_MSGS / "srv").glob("*.srv")):
        request, response = path.read_text().split("\n---\n")
        _register_service(store, f"polymap_msgs/srv/{path.stem}", request, response)


def _register_service(store, name, request_text, response_text):
    """A service's request and response, and the types REP 2016 hashes it with: the service
    itself (request_message, response_message, event_message) and its event message."""
    pkg = name.split("/")[0]
    parts = {}
    for suffix, text in (("Request", request_text), ("Response", response_text)):
        # Parsed under a msg name so that same-package references resolve, then renamed.
        parsed = get_types_from_msg(text, f"{pkg}/msg/{name.split('/')[2]}_{suffix}")
        ((_, (consts, fields)),) = parsed.items()
        parts[f"{name}_{suffix}"] = (consts, fields)
    store.register(parts)
    nested = lambda t: (Nodetype.NAME, t)  # noqa: E731
    at_most_one = lambda t: (Nodetype.SEQUENCE, ((Nodetype.NAME, t), 1))  # noqa: E731
    store.register({
        f"{name}_Event": ([], [
            ("info", nested("service_msgs/msg/ServiceEventInfo")),
            ("request", at_most_one(f"{name}_Request")),
            ("response", at_most_one(f"{name}_Response")),
        ]),
        name: ([], [
            ("request_message", nested(f"{name}_Request")),
            ("response_message", nested(f"{name}_Response")),
            ("event_message", nested(f"{name}_Event")),
        ]),
    })


def typestore():
    """ROS 2 Jazzy's types, plus polymap_msgs."""
    store = get_typestore(Stores.ROS2_JAZZY)
    # rosidl turns a .msg's `char` into uint8 before hashing (rosidl_adapter); rosbags keeps
    # it a char. ServiceEventInfo's client_gid is the only char field a hash here meets.
    consts, fields = store.fielddefs["service_msgs/msg/ServiceEventInfo"]
    fields = [(n, (Nodetype.ARRAY, ((Nodetype.BASE, ("uint8", 0)), 16)) if n == "client_gid" else t) for n, t in fields]
    store.fielddefs["service_msgs/msg/ServiceEventInfo"] = (consts, fields)
    _load_polymap_msgs(store)
    return store


def dds_name(typename):
    pkg, kind, name = typename.split("/")
    return f"{pkg}::{kind}::dds_::{name}_"


def mangle(name):
    return name.replace("/", "%")


def attachment(seq, gid):
    return struct.pack("<qq", seq, time.time_ns()) + bytes([16]) + gid


def parse_attachment(data):
    """(sequence number, source timestamp ns, gid) of a 33-byte attachment, or None."""
    if data is None or len(data) != 33 or data[16] != 16:
        return None
    seq, stamp = struct.unpack("<qq", data[:16])
    return seq, stamp, data[17:]


class Peer:
    """One node on one Zenoh session."""

    def __init__(self, connect, node="py_peer", namespace="/", domain=0, distro="jazzy"):
        self.store = typestore()
        self.domain = domain
        self.distro = distro
        self.node, self.namespace = node, namespace
        conf = zenoh.Config.from_json5(
            '{"mode": "peer", "connect": {"endpoints": ["%s"]}, "listen": {"endpoints": ["tcp/127.0.0.1:0"]},'
            ' "scouting": {"multicast": {"enabled": false}}}' % connect
        )
        self.session = zenoh.open(conf)
        self.zid = str(self.session.zid())
        self.next_id = 0
        self.keep = []
        self.node_id = self._id()
        self._token(self._prefix(self.node_id, "NN"))

    def close(self):
        self.keep.clear()
        self.session.close()

    def __enter__(self):
        return self

    def __exit__(self, *_):
        self.close()

    def _id(self):
        self.next_id += 1
        return self.next_id - 1

    def _prefix(self, entity_id, kind):
        ns = "%" if self.namespace == "/" else mangle(self.namespace)
        return f"@ros2_lv/{self.domain}/{self.zid}/{self.node_id}/{entity_id}/{kind}/%/{ns}/{self.node}"

    def _token(self, key):
        self.keep.append(self.session.liveliness().declare_token(key))

    def type_hash(self, typename):
        return "TypeHashNotSupported" if self.distro == "humble" else self.store.hash_rihs01(typename)

    def key(self, name, typename):
        return f"{self.domain}/{name.strip('/')}/{dds_name(typename)}/{self.type_hash(typename)}"

    def _entity(self, kind, name, typename, qos=DEFAULT_QOS):
        key = self.key(name, typename)
        token = f"{self._prefix(self._id(), kind)}/{mangle(name)}/{dds_name(typename)}/{self.type_hash(typename)}/{qos}"
        self._token(token)
        return key

    def subscribe(self, name, typename, callback, qos=DEFAULT_QOS):
        """callback(message, (seq, stamp, gid) or None) for every sample on the topic."""
        key = self._entity("MS", name, typename, qos)

        def on_sample(sample):
            att = sample.attachment.to_bytes() if sample.attachment is not None else None
            callback(self.store.deserialize_cdr(sample.payload.to_bytes(), typename), parse_attachment(att))

        self.keep.append(self.session.declare_subscriber(key, on_sample))
        return key

    def publisher(self, name, typename, qos=DEFAULT_QOS):
        key = self._entity("MP", name, typename, qos)
        gid = secrets.token_bytes(16)
        publisher = self.session.declare_publisher(key)
        self.keep.append(publisher)
        state = {"seq": 1}

        def put(message):
            publisher.put(bytes(self.store.serialize_cdr(message, typename)), attachment=attachment(state["seq"], gid))
            state["seq"] += 1

        return put

    def client(self, name, srvtype):
        key = self._entity("SC", name, srvtype)
        gid = secrets.token_bytes(16)
        state = {"seq": 1}

        def call(request, timeout=5.0):
            """The response, its attachment, and the request's sequence number."""
            seq = state["seq"]
            state["seq"] += 1
            replies = self.session.get(
                key,
                payload=bytes(self.store.serialize_cdr(request, f"{srvtype}_Request")),
                attachment=attachment(seq, gid),
                target=zenoh.QueryTarget.ALL_COMPLETE,
                consolidation=zenoh.ConsolidationMode.NONE,
                timeout=timeout,
            )
            for reply in replies:
                if reply.ok is None:
                    raise RuntimeError(f"{name}: error reply {reply.err.payload.to_bytes()!r}")
                sample = reply.ok
                att = sample.attachment.to_bytes() if sample.attachment is not None else None
                response = self.store.deserialize_cdr(sample.payload.to_bytes(), f"{srvtype}_Response")
                return response, parse_attachment(att), seq, gid
            raise TimeoutError(f"{name}: no reply within {timeout} s")

        return call

    def graph(self, timeout=2.0):
        """Every entity of the domain, as rmw_zenoh's graph cache parses the tokens."""
        entities = []
        for reply in self.session.liveliness().get(f"@ros2_lv/{self.domain}/**", timeout=timeout):
            if reply.ok is None:
                continue
            parts = str(reply.ok.key_expr).split("/")
            entity = {"zid": parts[2], "node_id": int(parts[3]), "id": int(parts[4]), "kind": parts[5],
                      "enclave": parts[6].replace("%", "/"), "namespace": parts[7].replace("%", "/"), "node": parts[8]}
            if len(parts) == 13:
                entity.update({"name": parts[9].replace("%", "/"), "type": parts[10], "hash": parts[11], "qos": parts[12]})
            entities.append(entity)
        return entities

    def wait_for(self, kind, name, timeout=60.0):
        """Blocks until another node has an entity of `kind` (MS: subscription, MP: publisher,
        SS: service) on `name` in the graph; raises TimeoutError after `timeout` s."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if any(e["kind"] == kind and e.get("name") == name and e["zid"] != self.zid
                   for e in self.graph(timeout=1.0)):
                return
            time.sleep(0.05)
        raise TimeoutError(f"no {kind} on {name} within {timeout} s")

    def msg(self, typename):
        """A message class of the store, to build messages to send."""
        return self.store.types[typename]


def connect_from_env(default="tcp/127.0.0.1:7447"):
    return os.environ.get("POLYMAP_CONNECT", default)
