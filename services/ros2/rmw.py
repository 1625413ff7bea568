"""rmw_zenoh's wire protocol, as text and bytes (pure: no session here).

What a ROS 2 node with RMW_IMPLEMENTATION=rmw_zenoh_cpp expects on the router (rmw_zenoh's design.md):
- data on `<domain>/<topic without leading slash>/<DDS type name>/<RIHS01 type hash>`, CDR payloads;
- each sample's attachment: sequence number (int64), source timestamp (int64 ns), publisher gid (16 bytes),
  in zenoh-ext serialisation: little-endian integers, the gid as a length-prefixed (LEB128) byte array;
- graph discovery by liveliness tokens under `@ros2_lv/<domain>/<zid>/<node id>/<entity id>/<kind>/...`: NN for
  the node, MP / MS for each publisher / subscription, with the topic, type, hash and QoS; names mangled
  ('/' -> '%');
- QoS in the token as `<reliability>:<durability>:<history kind>,<depth>:<deadline>:<lifespan>:<liveliness>`,
  empty fields meaning the default (reliable, volatile, keep-last).
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

from services.ros2.types import dds_type_name, type_hash

ADMIN_SPACE = "@ros2_lv"
GID_SIZE = 16
DEFAULT_DEPTH = 10
LATCHED_DEPTH = 1  # the publisher's cache: a late joiner gets the last value
TRANSIENT_LOCAL = 1  # rmw_zenoh's durability code in the QoS token


def mangle(name: str) -> str:
    """A ROS name as one key chunk: '/' -> '%' ('/' alone and '' -> '%')."""
    return "%" if name in ("", "/") else name.replace("/", "%")


def topic_key(domain_id: int, topic: str, type_name: str) -> str:
    return f"{domain_id}/{topic.strip('/')}/{dds_type_name(type_name)}/{type_hash(type_name)}"


def bridge_key(topic: str) -> str:
    """zenoh-bridge-ros2dds's key of a ROS topic (no namespace given to the bridge): the name without the leading
    '/'; the payload is the raw CDR, with neither type in the key nor attachment."""
    return topic.strip("/")


def qos_text(latched: bool) -> str:
    """Reliable, keep-last 10; latched: transient local, keep-last 1 (REP-155 ids: a late joiner gets the last)."""
    if latched:
        return f":{TRANSIENT_LOCAL}:,{LATCHED_DEPTH}:,:,:,,"
    return f"::,{DEFAULT_DEPTH}:,:,:,,"


@dataclass(frozen=True)
class NodeName:
    domain_id: int
    zid: str  # the zenoh session's id
    node_id: int
    name: str
    namespace: str

    def token(self) -> str:
        return (
            f"{ADMIN_SPACE}/{self.domain_id}/{self.zid}/{self.node_id}/{self.node_id}/NN/%/"
            f"{mangle(self.namespace)}/{mangle(self.name)}"
        )

    def endpoint_token(self, entity_id: int, kind: str, topic: str, type_name: str, qos: str) -> str:
        """The token of a publisher (kind MP) or subscription (MS) of this node."""
        return (
            f"{ADMIN_SPACE}/{self.domain_id}/{self.zid}/{self.node_id}/{entity_id}/{kind}/%/"
            f"{mangle(self.namespace)}/{mangle(self.name)}/{mangle(topic)}/"
            f"{dds_type_name(type_name)}/{type_hash(type_name)}/{qos}"
        )


def attachment(sequence_number: int, source_timestamp_ns: int, gid: bytes) -> bytes:
    if len(gid) != GID_SIZE:
        raise ValueError(f"a gid is {GID_SIZE} bytes, not {len(gid)}")
    return struct.pack("<qqB", sequence_number, source_timestamp_ns, GID_SIZE) + gid


def parse_attachment(data: bytes) -> tuple[int, int, bytes]:
    """(sequence number, source timestamp ns, gid); ValueError when it is not rmw_zenoh's layout."""
    if len(data) != 17 + GID_SIZE or data[16] != GID_SIZE:
        raise ValueError(f"not an rmw_zenoh attachment ({len(data)} bytes)")
    sequence_number, stamp = struct.unpack_from("<qq", data)
    return sequence_number, stamp, bytes(data[17:])
