"""Process shell of the ros2 service: the stack <-> ROS 2 over rmw_zenoh, on the stack's own router.

It reads the stack's persons, bodies, faces, objects, commands, clarifications and frames (for the intrinsics),
maps them with services/ros2/core.py and publishes them as a ROS 2 node would through rmw_zenoh: rmw key
expressions, CDR with rmw's attachment, liveliness tokens for the node and each endpoint, latched topics
through an AdvancedPublisher whose cache late joiners query. It subscribes a ROS camera and a text topic and
publishes them as the stack's Frame / DepthFrame / Transcript. docs/ros2.md.
"""

from __future__ import annotations

import argparse
import os
import struct
import threading
import time
from dataclasses import dataclass
from typing import Any, Callable

import zenoh
from zenoh import ext

from common.codec import decode
from common.image import jpeg_size, png_size
from common.runner import App, Delivery, Service, serve, service_parser
from common.schema import Frame, InvalidSample, RobotProfile
from common.settings import add_settings, from_args
from services.ros2 import core
from services.ros2.config import Ros2Config
from services.ros2.core import Outgoing
from services.ros2.rmw import LATCHED_DEPTH, NodeName, attachment, bridge_key, qos_text, topic_key
from services.ros2.types import deserialize, serialize

CDR = zenoh.Encoding("application/cdr")


def build_parser() -> argparse.ArgumentParser:
    p = service_parser("ros2", "hri-fusion as a ROS 2 node over rmw_zenoh (docs/ros2.md)")
    add_settings(p.add_argument_group("ROS 2"), Ros2Config)
    return p


@dataclass
class RosPublisher:
    key: str
    publisher: Any  # zenoh Publisher or AdvancedPublisher
    token: Any  # its liveliness token (None in the bridge layout: the bridge announces DDS endpoints itself)
    gid: bytes
    sequence: int = 0

    def put(self, payload: bytes) -> None:
        self.sequence += 1
        if self.token is None:
            self.publisher.put(payload)
            return
        stamp = attachment(self.sequence, time.time_ns(), self.gid)
        self.publisher.put(payload, encoding=CDR, attachment=stamp)

    def undeclare(self) -> None:
        self.publisher.undeclare()
        if self.token is not None:
            self.token.undeclare()


class RosNode:
    """One ROS 2 node on the rmw_zenoh graph: its token, its publishers (declared on first use) and
    subscriptions."""

    def __init__(self, session: zenoh.Session, config: Ros2Config):
        self.session = session
        self.config = config
        self.name = NodeName(config.domain_id, str(session.info.zid()), 0, config.node_name, config.namespace)
        self._entities = 0
        self._lock = threading.Lock()
        self._publishers: dict[str, RosPublisher] = {}
        self.rmw = config.key_layout == "rmw_zenoh"
        self._declared: list[Any] = [session.liveliness().declare_token(self.name.token())] if self.rmw else []

    def _next_entity(self) -> int:
        self._entities += 1
        return self._entities

    def publisher(self, out: Outgoing) -> RosPublisher:
        with self._lock:
            pub = self._publishers.get(out.topic)
            if pub is None:
                key = self.key(out.topic, out.type)
                if out.latched:  # transient local, as rmw_zenoh does it: a cache late joiners query
                    zpub: Any = ext.declare_advanced_publisher(
                        self.session, key, cache=ext.CacheConfig(max_samples=LATCHED_DEPTH), publisher_detection=True
                    )
                else:
                    zpub = self.session.declare_publisher(key)
                pub = self._publishers[out.topic] = RosPublisher(key, zpub, self._token("MP", out), os.urandom(16))
            return pub

    def key(self, topic: str, type_name: str) -> str:
        if self.rmw:
            return topic_key(self.config.domain_id, topic, type_name)
        return bridge_key(topic)

    def _token(self, kind: str, out: Outgoing) -> Any:
        """The liveliness token of a publisher (MP) or subscription (MS); None in the bridge layout."""
        if not self.rmw:
            return None
        qos = qos_text(out.latched)
        return self.session.liveliness().declare_token(
            self.name.endpoint_token(self._next_entity(), kind, out.topic, out.type, qos)
        )

    def publish(self, outs: list[Outgoing]) -> None:
        for out in outs:
            self.publisher(out).put(serialize(out.message, out.type))

    def subscribe(self, topic: str, type_name: str, handler: Callable[[Any], None]) -> None:
        """Receive `topic` from ROS; `handler` gets the deserialised message (on a zenoh thread)."""

        def on_sample(sample: zenoh.Sample) -> None:
            handler(sample.payload.to_bytes())

        self._declared.append(self.session.declare_subscriber(self.key(topic, type_name), on_sample))
        with self._lock:
            token = self._token("MS", Outgoing(topic, type_name, None))
        if token is not None:
            self._declared.append(token)

    def topics(self) -> list[str]:
        with self._lock:
            return list(self._publishers)

    def retire(self, topics: list[str]) -> None:
        """Undeclare the publishers (and tokens) of these topics: ros2 topic list stops showing them."""
        with self._lock:
            gone = [self._publishers.pop(t) for t in topics if t in self._publishers]
        for pub in gone:
            pub.undeclare()

    def close(self) -> None:
        for pub in self._publishers.values():
            pub.undeclare()
        for declared in reversed(self._declared):
            declared.undeclare()


class RosInputs:
    """The ROS side's camera, text and busy state, onto the stack (zenoh threads: one lock)."""

    def __init__(self, service: Service, node: RosNode, config: Ros2Config):
        self.service = service
        self.node = node
        self.config = config
        self.camera = core.CameraBridge(config, service.source, max_pixels=service.args.max_pixels)
        self.busy = False
        self._lock = threading.Lock()

    def subscribe_all(self) -> None:
        c, own = self.config, self.config.own
        wanted: list[tuple[str, str, Callable[[Any], None]]] = [
            (c.camera_info_topic, core.CAMERA_INFO, self.camera.set_info),
            (c.image_topic, core.IMAGE, self.on_image),
            (c.compressed_topic, core.COMPRESSED_IMAGE, self.on_compressed),
            (c.depth_topic, core.IMAGE, self.on_depth),
            (own(c.text_topic) if c.text_topic else "", core.STRING, self.on_text),
            (own(c.busy_topic) if c.busy_topic else "", core.BOOL, self.on_busy),
            (own(c.state_topic) if c.state_topic else "", core.STRING, self.on_state),
        ]
        for topic, type_name, handle in wanted:
            if topic:
                self.node.subscribe(topic, type_name, self._guarded(topic, type_name, handle))

    def _guarded(self, topic: str, type_name: str, handle: Callable[[Any], None]) -> Callable[[Any], None]:
        """Deserialise and handle one ROS message; a bad one is counted and dropped, never fatal."""

        def receive(payload: bytes) -> None:
            self.service.counters.add("received")
            try:
                message = deserialize(payload, type_name)
                with self._lock:
                    handle(message)
            except InvalidSample as exc:
                self.service.counters.reject(exc.reason, exc.detail, topic)
            except Exception as exc:  # a payload that is not this type's CDR
                self.service.counters.reject("bad_cdr", f"{type(exc).__name__}: {exc}", topic)

        return receive

    def on_image(self, image: Any) -> None:
        self._publish_frame(self.camera.frame(image, time.time()))

    def on_compressed(self, image: Any) -> None:
        data = bytes(image.data)
        try:
            size = png_size(data) if "png" in image.format.lower() else jpeg_size(data)
        except (ValueError, struct.error) as exc:
            raise InvalidSample("bad_value", f"{image.format} header unreadable: {exc}") from None
        self._publish_frame(self.camera.compressed_frame(image, time.time(), size))

    def _publish_frame(self, frame: Frame) -> None:
        self.service.publish_output("frame", frame, lossless=False, cam=self.config.cam)

    def on_depth(self, image: Any) -> None:
        depth = self.camera.depth(image, time.time())
        self.service.publish_output("depth", depth, lossless=False, cam=self.config.cam)

    def on_text(self, message: Any) -> None:
        transcript = core.text_transcript(message.data, time.time(), self.service.source)
        if transcript is not None:
            key = self.service.keys.key("transcript", mic=core.TEXT_MIC)
            self.service.publish(key, transcript)
            self.service.log.info("text command from ROS: %r", transcript.text)

    def on_busy(self, message: Any) -> None:
        self.busy = bool(message.data)

    def on_state(self, message: Any) -> None:
        state = core.robot_state(message.data, time.time(), self.service.source)
        self.service.publish_output("robot_state", state)
        self.service.log.info("robot state from ROS: %s%s", state.status, f" ({state.reason})" if state.reason else "")


class Ros2App(App):
    """The stack's persons, bodies, faces, objects, commands, questions and camera intrinsics -> ROS 2 messages
    (services/ros2/core.py); a ROS camera and text topic -> Frame / DepthFrame / Transcript (RosInputs)."""

    node = "ros2"
    recovering = True  # timestamping: latched topics use AdvancedPublishers

    def __init__(self, args: argparse.Namespace) -> None:
        self.config = from_args(Ros2Config, args)
        self.latch = core.Latch()
        self.tracked = core.Tracked()

    def wire(self, service: Service) -> None:
        assert service.session is not None  # wired once connected
        config, latch = self.config, self.latch
        self.service = service
        self.ros = RosNode(service.session, config)
        service.on_close(self.ros.close)
        self.inputs = RosInputs(service, self.ros, config)
        service.subscribe_input("persons", self.publishing(lambda s: core.persons_messages(s, config, latch)))
        service.subscribe_input("bodies", self.publishing(lambda s: core.bodies_messages(s, config)))
        service.subscribe_input("faces", self.publishing(lambda s: core.faces_messages(s, config)))
        service.subscribe_input("objects", self.publishing(lambda s: core.detections_messages(s, config)))
        service.subscribe_input("command", self.on_command)
        service.subscribe_input("clarification", self.publishing(lambda s: core.clarification_messages(s, config)))
        service.subscribe_input("frame", self.publishing(lambda s: core.camera_info_messages(s, config, latch)))
        profile = self.publishing(lambda s: core.profile_messages(s, config, latch))
        service.subscribe_input("robot_profile", profile)  # the robot's profile, from fusion (docs/robot.md)
        self.inputs.subscribe_all()
        for reply in service.session.get(service.keys.robot_profile(), timeout=2.0):  # fusion started first
            if reply.ok is not None:
                try:
                    sample = decode(reply.ok.payload.to_bytes(), RobotProfile)
                except InvalidSample as exc:
                    service.counters.reject(exc.reason, exc.detail, "robot/profile")
                    continue
                self.ros.publish(core.profile_messages(sample, config, latch))
        service.log.info(
            "ROS 2 node %s%s on domain %d (rmw_zenoh)",
            config.namespace.rstrip("/") + "/",
            config.node_name,
            config.domain_id,
        )

    def retire_the_gone(self, cam: str, outs: list[Outgoing]) -> None:
        """Per-id topics of people no camera tracks any more go, and their latched values are forgotten."""
        for kind, ids in core.tracked_ids(outs, self.config).items():
            self.tracked.update(kind, cam, ids)
            gone = self.tracked.gone(kind, self.ros.topics(), self.config)
            if gone:
                self.ros.retire(gone)
                for topic in gone:
                    self.latch.forget(topic)
                self.service.counters.add("ros_topics_retired", len(gone))

    def publishing(self, convert: Callable[[Any], list[Outgoing]]) -> Callable[[Delivery], None]:
        def handle(delivery: Delivery) -> None:
            outs = convert(delivery.sample)
            self.ros.publish(outs)
            self.service.counters.add("ros_published", len(outs))
            self.retire_the_gone(getattr(delivery.sample, "cam", ""), outs)

        return handle

    def on_command(self, delivery: Delivery) -> None:
        if not core.passes_while_busy(delivery.sample, self.inputs.busy):
            self.service.counters.add("held_while_busy")
            self.service.log.info("robot busy: %s %s not forwarded", delivery.sample.intent, delivery.sample.id)
            return
        self.publishing(lambda cmd: core.fused_command_messages(cmd, self.config))(delivery)


def main(argv: list[str] | None = None) -> None:
    args = build_parser().parse_args(argv)
    serve(Ros2App(args), args)


if __name__ == "__main__":
    main()
