"""rmw_zenoh's key expressions, liveliness tokens, attachment and QoS text, checked against zenoh-ros2-sdk's
independent implementation of the same protocol."""

from __future__ import annotations

import pytest

sdk_keyexpr = pytest.importorskip("zenoh_ros2_sdk.keyexpr")

from zenoh_ros2_sdk.attachment import Attachment  # noqa: E402
from zenoh_ros2_sdk.entity import EndpointEntity, EntityKind, NodeEntity  # noqa: E402
from zenoh_ros2_sdk.qos import QosDurability, QosHistoryKind, QosProfile, QosReliability  # noqa: E402

from services.ros2 import rmw  # noqa: E402
from services.ros2.types import dds_type_name, type_hash  # noqa: E402

TOPIC, TYPE = "/humans/persons/p_1/face_id", "std_msgs/msg/String"
NODE = rmw.NodeName(domain_id=3, zid="a1b2c3", node_id=0, name="hri_fusion", namespace="/robot7/hri")
SDK_NODE = NodeEntity(domain_id=3, session_id="a1b2c3", node_id=0, node_name="hri_fusion", namespace="/robot7/hri")


def test_data_key_expression():
    assert rmw.topic_key(3, TOPIC, TYPE) == sdk_keyexpr.topic_keyexpr(3, TOPIC, dds_type_name(TYPE), type_hash(TYPE))
    assert rmw.topic_key(0, "/chatter", TYPE) == (
        "0/chatter/std_msgs::msg::dds_::String_/RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18"
    )


def test_node_and_endpoint_tokens():
    assert NODE.token() == sdk_keyexpr.node_liveliness_keyexpr(SDK_NODE)
    for kind, sdk_kind, latched in (("MP", EntityKind.PUBLISHER, True), ("MS", EntityKind.SUBSCRIPTION, False)):
        ours = NODE.endpoint_token(7, kind, TOPIC, TYPE, rmw.qos_text(latched))
        theirs = sdk_keyexpr.endpoint_liveliness_keyexpr(
            EndpointEntity(SDK_NODE, 7, sdk_kind, TOPIC, dds_type_name(TYPE), type_hash(TYPE), rmw.qos_text(latched))
        )
        assert ours == theirs
        assert "/%humans%persons%p_1%face_id/" in ours and "/%robot7%hri/" in ours


def test_qos_text_decodes_as_meant():
    latched = QosProfile.decode(rmw.qos_text(True))
    assert latched.durability == QosDurability.TRANSIENT_LOCAL
    assert (latched.history_kind, latched.history_depth) == (QosHistoryKind.KEEP_LAST, rmw.LATCHED_DEPTH)
    assert latched.reliability == QosReliability.RELIABLE
    volatile = QosProfile.decode(rmw.qos_text(False))
    assert volatile.durability == QosDurability.VOLATILE and volatile.history_depth == rmw.DEFAULT_DEPTH
    assert rmw.qos_text(False) == QosProfile().encode()


def test_attachment_layout():
    gid = bytes(range(16))
    data = rmw.attachment(42, 1_790_000_000_123_456_789, gid)
    parsed = Attachment.from_bytes(data)
    assert (parsed.sequence_id, parsed.timestamp_ns, parsed.gid) == (42, 1_790_000_000_123_456_789, gid)
    assert data == Attachment(42, 1_790_000_000_123_456_789, gid).to_bytes()
    assert rmw.parse_attachment(data) == (42, 1_790_000_000_123_456_789, gid)
    # rmw_zenoh writes it with zenoh-ext's serializer: int64, int64, then the gid as a byte sequence
    from zenoh import ext

    serialized = ext.z_serialize((ext.Int64(42), ext.Int64(1_790_000_000_123_456_789), gid))
    assert data == serialized.to_bytes()
    with pytest.raises(ValueError):
        rmw.attachment(1, 1, b"short")
    with pytest.raises(ValueError):
        rmw.parse_attachment(data[:-1])
