"""Process shell of the fusion service: speech + vision + gesture -> FusedCommand / Clarification."""

from __future__ import annotations

import argparse
import gc
import queue
import time
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any, Callable, Iterator

import zenoh

from common.codec import ENCODING, encode
from common.engagement import EngagementConfig
from common.robot import DEFAULT, Profile, ProfileError, load_profile
from common.runner import App, Delivery, RateLimitedLog, Service, StartupError, serve, service_parser
from common.schema import Clarification, FusedCommand
from common.settings import add_settings, from_args, setting
from services.fusion.core import Config, FusionCore
from services.fusion.join import ClockOffsets, clock_verdict
from services.fusion.outputs import Output
from services.fusion.speaker import SpeakerConfig

DEFAULTS = Config()
EPILOG = f"""\
examples:
  hri-fusion                                   # adaptive weights, defaults below
  hri-fusion --weights fixed                   # constant modality weights (for comparison)
  hri-fusion --window-before 1.5 --max-wait 0.8
  hri-fusion --profile profiles/mobile_manipulator.toml   # what this robot can do (docs/robot.md)
  hri echo 'hri/fusion/**'                     # watch its commands and questions

defaults: window [start - {DEFAULTS.window_before:g} s, end + {DEFAULTS.window_after:g} s] of source time,
decide when every live modality's latest stamp has passed the window end or {DEFAULTS.max_wait:g} s (wall)
after the transcript arrived; a clarification stays open {DEFAULTS.dialogue_timeout:g} s; a modality is live
while its service's liveliness token exists or it sent a sample in the last {DEFAULTS.live_recent_s:g} s.

clocks: each source's clock offset against this machine's is estimated from the router's Zenoh timestamps
(`hri stats fusion`: other["clock_offset_ms:SOURCE"]; a source of transcripts, late by design, shows its
recognition delay as other["delay_ms:SOURCE"] instead unless its clock runs ahead); a warning is logged (at
most every 30 s per source) when a source runs more than half the window after its end ahead, or half the window
before its start behind.
"""


@contextmanager
def collector_after_output() -> Iterator[None]:
    """A decision and the publishing of its output run with the cyclic garbage collector paused: a decision over
    1000 objects allocates enough to set off a collection in its middle (issue #34: 1-2 ms of its p99). The pass
    runs at the next allocation after, once the command is out; nothing is skipped, only moved."""
    was_enabled = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if was_enabled:
            gc.enable()


@dataclass(frozen=True)
class RobotSettings:
    """Which robot fusion serves (docs/robot.md)."""

    profile: str | None = setting(
        None,
        "the robot's profile (TOML): what it may grasp, weight and size limits, whether it carries, navigates, "
        "speaks, what a command while busy does; none: the built-in default (profiles/default.toml)",
        metavar="FILE",
    )


CLOCK_WARN_SHARE = 0.5  # warn when a source's clock offset uses more than this share of the window's margin


def build_parser() -> argparse.ArgumentParser:
    parser = service_parser(
        "fusion",
        "Join speech, vision and gesture on source time and publish grounded "
        "commands (FusedCommand) and questions (Clarification).",
        EPILOG,
    )
    add_settings(parser.add_argument_group("fusion (docs/fusion.md, Settings)"), Config)
    add_settings(parser.add_argument_group("who is speaking (docs/people.md)"), SpeakerConfig)
    add_settings(parser.add_argument_group("the robot (docs/robot.md)"), RobotSettings)
    add_settings(parser.add_argument_group("engagement: said to the robot? (docs/people.md)"), EngagementConfig)
    return parser


class ClockReport:
    """Fusion's clock estimates (ClockOffsets) as `Stats.other` gauges, once a second, and the warning."""

    def __init__(self, service: Service, config: Config):
        self.estimates = ClockOffsets()
        self.service = service
        self.log = RateLimitedLog(service.log, interval=30.0)
        self.ahead_tol = CLOCK_WARN_SHARE * config.window_after
        self.behind_tol = CLOCK_WARN_SHARE * config.window_before
        self.last_report = 0.0

    def forget(self, source: str) -> None:
        self.estimates.forget(source)
        self._clear(source)

    def _clear(self, source: str) -> None:
        self.service.counters.set(f"clock_offset_ms:{source}", None)
        self.service.counters.set(f"delay_ms:{source}", None)

    def report(self, now: float) -> None:
        if now - self.last_report < 1.0:
            return
        self.last_report = now
        counters = self.service.counters
        for source in self.estimates.expire(now):
            self._clear(source)
        for source, delay in self.estimates.delays().items():
            counters.set(f"clock_offset_ms:{source}", None)
            counters.set(f"delay_ms:{source}", round(delay * 1000))
        for source, offset in self.estimates.offsets().items():
            counters.set(f"clock_offset_ms:{source}", round(offset * 1000))
            counters.set(f"delay_ms:{source}", None)
            self._warn(source, offset)

    def _warn(self, source: str, offset: float) -> None:
        verdict = clock_verdict(offset, self.ahead_tol, self.behind_tol)
        if verdict is not None:
            self.log.warn(
                f"clock:{source}",
                f"{source}'s stamps run {abs(offset) * 1000:.0f} ms {verdict} of "
                f"this machine's clock (tolerated: {self.ahead_tol * 1000:.0f} ms ahead, "
                f"{self.behind_tol * 1000:.0f} ms behind): its words, points and detections are joined "
                f"at the wrong moment. Keep the hosts in step with chrony or PTP "
                f"(docs/foundation.md); `hri stats fusion` shows every source's offset",
            )


def publish_outputs(service: Service, outputs: list[Output], command_key: str, clarification_key: str) -> None:
    for out in outputs:
        sample = out.sample
        if isinstance(sample, FusedCommand):
            # stops go out at REAL_TIME priority, express; everything is BLOCK (never dropped)
            service.publish(command_key, sample, lossless=True, realtime=out.realtime, recovering=True)
            service.log.info(
                "command %s %s%s: %s",
                sample.id,
                sample.intent,
                f" -> {sample.target.id}" if sample.target else "",
                sample.explanation,
            )
        elif isinstance(sample, Clarification):
            service.publish(clarification_key, sample, lossless=True, recovering=True)
            service.log.info("clarification %s (%s): %s", sample.id, sample.reason, sample.question)


Feed = Callable[[str, Any, float], list[Output]]


class FusionApp(App):
    """Transcripts, objects, hands, gesture events, bodies, faces and persons -> FusionCore -> FusedCommand /
    Clarification."""

    node = "fusion"
    recovering = True  # commands survive a dropped link (common/transport.py)
    tick_interval = 0.02

    def __init__(self, args: argparse.Namespace) -> None:
        self.config = from_args(Config, args)
        self.speaker = from_args(SpeakerConfig, args)
        self.profile_path = from_args(RobotSettings, args).profile
        self.profile: Profile = DEFAULT
        self.engagement = from_args(EngagementConfig, args)
        # Liveliness callbacks run on zenoh threads; the core belongs to the worker: hand over via a queue.
        self.liveliness_events: queue.SimpleQueue[tuple[str, str, bool]] = queue.SimpleQueue()

    def open(self, service: Service) -> None:
        self.service = service
        try:
            self.profile = load_profile(self.profile_path)
        except ProfileError as exc:  # refused at start: nothing runs with a profile that says something else
            raise StartupError(str(exc)) from None
        self.core = FusionCore(
            self.config,
            service.source,
            count=service.counters.add,
            log=service.log,
            speaker=self.speaker,
            profile=self.profile,
            engagement=self.engagement,
        )
        self.clocks = ClockReport(service, self.config)
        self.command_key = service.output_key("command")
        self.clarification_key = service.output_key("clarification")
        self.tick = self.tick_once

    def wire(self, service: Service) -> None:
        assert service.session is not None  # wired once connected
        token_sub = service.session.liveliness().declare_subscriber(
            service.keys.alive("*", "*"), self.on_token, history=True
        )
        service.on_close(token_sub.undeclare)
        core = self.core
        service.subscribe_input("transcript", self.handler(core.on_transcript, delayed=True))
        service.subscribe_input("objects", self.handler(core.on_detections))
        service.subscribe_input("hands", self.handler(core.on_hands))
        service.subscribe_input("event", self.handler(core.on_gesture_event))
        service.subscribe_input("bodies", self.handler(core.on_bodies))  # which way the speaker faces
        service.subscribe_input("faces", self.handler(core.on_faces))  # who is speaking
        service.subscribe_input("persons", self.handler(core.on_persons))  # people in view: "bring it to me"
        service.subscribe_input("robot_state", self.handler(core.on_robot_state))  # what the robot is doing
        # what the robot said and when: a question's answer window opens when it was said (stamped at its start, sent
        # before it plays: no clock estimate from it)
        service.subscribe_input("spoken", self.handler(core.on_spoken, clocked=False))
        self.announce_profile(service)
        config = self.config
        service.log.info(
            "fusion: window [start-%.2f, end+%.2f] s, max wait %.2f s, %s weights%s",
            config.window_before,
            config.window_after,
            config.max_wait,
            config.weights,
            ", fallback to the most confident detection" if config.fallback_most_confident else "",
        )
        # What start-up made (modules, zenoh, numpy, the language tables) lives as long as the process: frozen out of
        # the cyclic collector's reach, a full collection during a decision walks only what came since (issue #34:
        # a decision over 1000 objects allocates enough to trigger one; benchmarks/fusion.py does the same)
        gc.freeze()

    def announce_profile(self, service: Service) -> None:
        """The robot's profile on the wire: published once now, and answered to every query of its key (Zenoh keeps
        no last value: a consumer that starts later asks, docs/robot.md)."""
        assert service.session is not None
        key = service.output_key("robot_profile")
        sample = self.profile.sample(time.time(), service.source)
        payload = encode(sample)

        def answer(query: zenoh.Query) -> None:
            try:
                query.reply(key, payload, encoding=ENCODING)
            except Exception as exc:  # a reply must never take the service down
                service.log.warning("could not answer a profile query: %s", exc)

        queryable = service.session.declare_queryable(key, answer)
        service.on_close(queryable.undeclare)
        service.publish(key, sample)
        service.log.info(
            "robot profile %s%s: %s",
            self.profile.name,
            f" ({self.profile.path})" if self.profile.path else "",
            self.profile.words(),
        )

    def on_token(self, sample: zenoh.Sample) -> None:
        parsed = self.service.keys.parse_alive(str(sample.key_expr))
        if parsed:
            self.liveliness_events.put((*parsed, sample.kind == zenoh.SampleKind.PUT))

    def handler(self, feed: Feed, delayed: bool = False, clocked: bool = True) -> Callable[[Delivery], None]:
        def handle(d: Delivery) -> None:
            self.service.log.debug("in %s %.3f", d.key, d.sample.stamp)
            # a transcript is stamped at the utterance's end and published after recognition (0.2-2 s later): late
            # by design, so that delay is reported as such (delay_ms:SOURCE), never read as the clock running behind
            if clocked:
                self.clocks.estimates.add(
                    d.sample.source, d.sample.stamp, d.zenoh_time, d.received_at, late_by_design=delayed
                )
            with collector_after_output():
                self.emit(feed(d.key, d.sample, d.received_at))

        return handle

    def emit(self, outputs: list[Output]) -> None:
        publish_outputs(self.service, outputs, self.command_key, self.clarification_key)

    def tick_once(self) -> None:
        while True:
            try:
                service_name, instance, present = self.liveliness_events.get_nowait()
            except queue.Empty:
                break
            self.core.on_liveliness(service_name, instance, present)
            if not present:  # a restarted instance starts a new estimate
                self.clocks.forget(f"{service_name}/{instance}")
        now = time.time()
        self.clocks.report(now)
        with collector_after_output():
            self.emit(self.core.tick(now))


def main(argv: list[str] | None = None) -> None:
    args = build_parser().parse_args(argv)
    serve(FusionApp(args), args)


if __name__ == "__main__":
    main()
