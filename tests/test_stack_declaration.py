"""The stack is declared once (common/stack.py); keys, roles, subscriptions and fusion's modalities follow it.

Pure: no router, no session. The last test adds a fictional node to the declaration and shows that everything
derived picks it up with no other edit.
"""

from __future__ import annotations

import dataclasses
import logging

import pytest
import zenoh

import common.stack as stack
from common.keys import KEY_TABLE, Keys, key_table
from common.runner import Service, UndeclaredTopic, service_parser
from common.schema import MODALITY_NAMES, Detections, Frame
from common.security import (
    DEFAULT_USERS,
    ROLES,
    Secrets,
    access_control,
    may_publish,
    stack_default_users,
    stack_roles,
)
from common.stack import CLIENTS, NODES, TOPICS, Input, Node, Topic, node, publishers_of
from services.fusion.core import MODALITIES, input_services, modality_of
from services.fusion.join import WAITED_MODALITIES, waited_modalities


def concrete(topic: Topic, prefix: str = "hri") -> str:
    """The topic's key with every placeholder filled by a name."""
    return f"{prefix}/" + topic.pattern.format(**{p: f"{p}1" for p in topic.placeholders()})


def secrets_of(users: dict[str, list[str]], roles=None) -> Secrets:
    return Secrets(folder=None, users=users, roles=dict(roles or ROLES))  # type: ignore[arg-type]


# -- keys ---------------------------------------------------------------------------------------------------------


def test_every_topic_has_its_key_and_its_schema():
    keys = Keys("lab/robot7")
    assert KEY_TABLE == key_table() == tuple((t.pattern, t.schema) for t in TOPICS)
    for t in TOPICS:
        key = keys.key(t.name, **{p: f"{p}1" for p in t.placeholders()})
        assert key == concrete(t, "lab/robot7")
        assert keys.schema_for(key) is t.schema, t.name
        assert keys.key(t.name) == f"lab/robot7/{t.wildcard()}"  # a chunk not given is the wildcard
    assert keys.schema_for("lab/robot7/camera/c1/frame/extra") is None
    assert keys.schema_for("hri/camera/c1/frame") is None  # another prefix


def test_the_named_key_methods_are_the_topics():
    keys = Keys()
    assert keys.frame("front") == keys.key("frame", cam="front") == "hri/camera/front/frame"
    assert keys.depth("front") == "hri/camera/front/depth"
    assert keys.audio() == "hri/audio/*/pcm"
    assert keys.objects("front") == "hri/vision/front/objects"
    assert keys.hands("c") == "hri/gesture/c/hands" and keys.bodies("c") == "hri/gesture/c/bodies"
    assert keys.gesture_event("c") == "hri/gesture/c/event"
    assert keys.transcript("kbd") == "hri/speech/kbd/transcript"
    assert keys.command() == "hri/fusion/command" and keys.clarification() == "hri/fusion/clarification"
    assert keys.stats("vision", "h-1") == "hri/stats/vision/h-1"


def test_a_bad_chunk_or_placeholder_is_refused_with_its_name():
    keys = Keys()
    with pytest.raises(ValueError, match="invalid camera id 'a/b'"):
        keys.key("frame", cam="a/b")
    with pytest.raises(ValueError, match="invalid microphone id"):
        keys.transcript("m*")
    with pytest.raises(ValueError, match="no placeholder"):
        keys.key("frame", mic="m1")
    with pytest.raises(KeyError, match="common/stack.py"):
        keys.key("radar")


# -- roles --------------------------------------------------------------------------------------------------------


def test_each_node_publishes_exactly_its_outputs_and_reads_exactly_its_inputs():
    users = {n.name: [n.name] for n in NODES}
    sec = secrets_of(users)
    for n in NODES:
        role = ROLES[n.name]
        assert set(role.publish) == {stack.topic(t).wildcard() for t in n.outputs} | set(n.fixed_keys), n.name
        for key in n.fixed_keys:  # exact keys besides its outputs (the ros2 node's typed commands)
            assert may_publish(sec, n.name, f"hri/{key}", "hri"), (n.name, key)
        assert set(role.subscribe) == {stack.topic(i.topic).wildcard() for i in n.inputs}, n.name
        assert role.service == n.name
        for t in TOPICS:
            # may_publish is what the router's rules allow (the same key expressions)
            assert may_publish(sec, n.name, concrete(t), "hri") == (t.name in n.outputs), (n.name, t.name)
        for i in n.inputs:  # the subscription the service declares passes its role's rules
            wanted = zenoh.KeyExpr(f"hri/{stack.topic(i.topic).wildcard()}")
            assert any(zenoh.KeyExpr(f"hri/{e}").includes(wanted) for e in role.subscribe), (n.name, i.topic)


def test_a_node_may_not_publish_another_nodes_topic():
    sec = secrets_of({"vision": ["vision"], "gesture": ["gesture"]})
    assert may_publish(sec, "vision", "hri/vision/cam0/objects", "hri")
    assert not may_publish(sec, "vision", "hri/fusion/command", "hri")
    assert not may_publish(sec, "vision", "hri/vision/cam0/anything_else", "hri")  # narrower than vision/**
    assert not may_publish(sec, "gesture", "hri/vision/cam0/objects", "hri")
    rules = {r["id"]: r for r in access_control(sec, "hri")["rules"]}
    assert rules["vision-publish"]["key_exprs"] == ["hri/vision/*/objects"]
    assert rules["gesture-publish"]["key_exprs"] == [
        "hri/gesture/*/hands",
        "hri/gesture/*/bodies",
        "hri/gesture/*/event",
        "hri/gesture/*/faces",
        "hri/gesture/*/persons",
    ]


def test_clients_have_the_declared_roles():
    sec = secrets_of({"cli": ["reader"], "mic": ["mic"], "say": ["keyboard"], "replay": ["replay"]})
    assert ROLES["reader"].subscribe == ("**",) and not ROLES["reader"].publish
    assert not any(may_publish(sec, "cli", concrete(t), "hri") for t in TOPICS)
    assert [t.name for t in TOPICS if may_publish(sec, "mic", concrete(t), "hri")] == ["audio"]
    assert may_publish(sec, "say", "hri/speech/kbd/transcript", "hri")
    assert not may_publish(sec, "say", "hri/speech/mic1/transcript", "hri")
    replayed = {t.name for t in TOPICS if may_publish(sec, "replay", concrete(t), "hri")}
    assert replayed == {t for n in NODES if n.name != "fusion" for t in n.outputs} | {"audio"}
    assert DEFAULT_USERS == {**{n.name: [n.name] for n in NODES}, "mic": ["mic"], "cli": ["reader"]}
    assert set(ROLES) == {n.name for n in NODES} | {c.name for c in CLIENTS}


# -- subscriptions ------------------------------------------------------------------------------------------------


def make_service(name: str) -> Service:
    # --nice 0 --cv-threads 0: a Service applies both to its whole process, here the test process (tests/conftest.py)
    args = service_parser(name, "test").parse_args(["--nice", "0", "--cv-threads", "0"])
    return Service(name, args, log=logging.getLogger(f"test.{name}"))


def test_subscribe_input_takes_everything_from_the_declaration(monkeypatch):
    service = make_service("vision")
    calls = []
    monkeypatch.setattr(service, "_subscribe", lambda key, schema, handler, **kw: calls.append((key, schema, kw)))
    service.subscribe_input("frame", print, cam="front")
    service.subscribe_input("depth", print)
    assert calls == [
        ("hri/camera/front/frame", Frame, {"latest": True, "maxlen": 1000, "monotonic": True, "image": True}),
        (
            "hri/camera/*/depth",
            stack.topic("depth").schema,
            dict(latest=True, maxlen=1000, monotonic=True, image=False),
        ),
    ]
    fusion = make_service("fusion")
    monkeypatch.setattr(fusion, "_subscribe", lambda key, schema, handler, **kw: calls.append((key, schema, kw)))
    fusion.subscribe_input("objects", print)
    assert calls[-1] == (
        "hri/vision/*/objects",
        Detections,
        dict(latest=False, maxlen=300, monotonic=False, image=False),
    )


def test_an_undeclared_topic_fails_at_start_up_naming_the_declaration():
    service = make_service("vision")
    with pytest.raises(UndeclaredTopic, match=r"vision subscribes to 'audio'.*common/stack\.py"):
        service.subscribe_input("audio", print)
    with pytest.raises(UndeclaredTopic, match=r"vision publishes on 'command'.*common/stack\.py"):
        service.output_key("command")
    assert service.output_key("objects", cam="c1") == "hri/vision/c1/objects"
    with pytest.raises(KeyError, match="common/stack.py"):
        make_service("radar")


def test_only_nodes_that_read_images_take_max_pixels():
    for n in NODES:
        flags = {a.dest for a in service_parser(n.name, "test")._actions}
        assert ("max_pixels" in flags) == n.reads_images, n.name
    assert {n.name for n in NODES if n.reads_images} == {"vision", "gesture", "ros2"}  # ros2: for the intrinsics


# -- fusion's modalities ------------------------------------------------------------------------------------------


def test_fusion_modalities_are_the_publishers_of_its_inputs():
    assert MODALITIES == ("speech", "vision", "gesture")
    assert set(MODALITY_NAMES) <= set(MODALITIES)  # the contract's weighed modalities are services that feed fusion
    assert WAITED_MODALITIES == ("vision", "gesture")  # bodies and transcripts are not waited for
    assert [modality_of(s) for s in ("speech", "vision", "gesture", "camera", "fusion")] == [
        "speech",
        "vision",
        "gesture",
        None,
        None,
    ]


# -- adding a node is one entry -----------------------------------------------------------------------------------


def test_adding_a_node_is_one_entry(monkeypatch):
    """A radar node with a topic of its own, joined by fusion: keys, roles, users, the parser and fusion's
    modalities follow with no other edit."""
    tracks = Topic("tracks", "radar/{radar}/tracks", Detections, "objects seen by a radar")
    radar = Node("radar", "objects from a radar", outputs=("tracks",))
    fusion = node("fusion")
    joined = dataclasses.replace(fusion, inputs=(*fusion.inputs, Input("tracks", "fifo", maxlen=100, joined=True)))
    monkeypatch.setattr(stack, "TOPICS", (*TOPICS, tracks))
    monkeypatch.setattr(stack, "NODES", tuple(joined if n.name == "fusion" else n for n in NODES) + (radar,))
    stack.check_stack()

    keys = Keys()
    assert keys.key("tracks", radar="r1") == "hri/radar/r1/tracks"
    assert keys.schema_for("hri/radar/r1/tracks") is Detections
    assert ("radar/{radar}/tracks", Detections) in key_table()

    roles = stack_roles()
    assert roles["radar"].publish == ("radar/*/tracks",) and roles["radar"].service == "radar"
    assert "radar/*/tracks" in roles["fusion"].subscribe
    assert stack_default_users()["radar"] == ["radar"]
    sec = secrets_of({"radar": ["radar"], "vision": ["vision"]}, roles)
    assert may_publish(sec, "radar", "hri/radar/r1/tracks", "hri")
    assert not may_publish(sec, "vision", "hri/radar/r1/tracks", "hri")

    assert publishers_of("tracks") == ["radar"]
    assert waited_modalities() == ("vision", "gesture", "radar")
    assert input_services() == ("speech", "vision", "gesture", "radar")

    service = make_service("radar")
    assert service.output_key("tracks", radar="r1") == "hri/radar/r1/tracks"
    assert "max_pixels" not in {a.dest for a in service_parser("radar", "test")._actions}


def test_a_node_reading_images_must_say_so(monkeypatch):
    blind = Node("blind", "reads frames but forgot reads_images", inputs=(Input("frame", "latest"),))
    monkeypatch.setattr(stack, "NODES", (*NODES, blind))
    with pytest.raises(ValueError, match="node blind reads the image topic"):
        stack.check_stack()
