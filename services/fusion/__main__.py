"""Process shell of the fusion service: speech + vision + gesture -> FusedCommand / Clarification."""

from __future__ import annotations

import argparse
import queue
import time

import zenoh

from common.runner import Delivery, RateLimitedLog, Service, main_exit, service_parser
from common.schema import Clarification, FusedCommand
from common.settings import add_settings, from_args
from services.fusion.core import Config, FusionCore
from services.fusion.join import ClockOffsets, clock_verdict
from services.fusion.outputs import Output

DEFAULTS = Config()
EPILOG = f"""\
examples:
  hri-fusion                                   # adaptive weights, defaults below
  hri-fusion --weights fixed                   # constant modality weights (for comparison)
  hri-fusion --window-before 1.5 --max-wait 0.8
  hri echo 'hri/fusion/**'                     # watch its commands and questions

defaults: window [start - {DEFAULTS.window_before:g} s, end + {DEFAULTS.window_after:g} s] of source time,
decide when every live modality's latest stamp has passed the window end or {DEFAULTS.max_wait:g} s (wall)
after the transcript arrived; a clarification stays open {DEFAULTS.dialogue_timeout:g} s; a modality is live
while its service's liveliness token exists or it sent a sample in the last {DEFAULTS.live_recent_s:g} s.

clocks: each source's clock offset against this machine's is estimated from the router's Zenoh timestamps
(`hri stats fusion`: other["clock_offset_ms:SOURCE"]); a warning is logged (at most every 30 s per source)
when a source runs more than half the window after its end ahead, or half the window before its start behind.
"""


CLOCK_WARN_SHARE = 0.5  # warn when a source's clock offset uses more than this share of the window's margin


def build_parser() -> argparse.ArgumentParser:
    parser = service_parser(
        "fusion",
        "Join speech, vision and gesture on source time and publish grounded "
        "commands (FusedCommand) and questions (Clarification).",
        EPILOG,
    )
    add_settings(parser.add_argument_group("fusion (docs/fusion.md, Settings)"), Config)
    return parser


def main(argv: list[str] | None = None) -> None:
    args = build_parser().parse_args(argv)

    service = Service("fusion", args, recovering=True)
    config = from_args(Config, args)
    core = FusionCore(config, service.source, count=service.counters.add, log=service.log)
    if not service.connect():
        main_exit(0)
    keys = service.keys
    assert service.session is not None
    command_key, clarification_key = service.output_key("command"), service.output_key("clarification")

    def emit(outputs: list[Output]) -> None:
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

    # Liveliness callbacks run on zenoh threads; the core belongs to the worker: hand over via a queue.
    liveliness_events: queue.SimpleQueue[tuple[str, str, bool]] = queue.SimpleQueue()

    def on_token(sample: zenoh.Sample) -> None:
        parsed = keys.parse_alive(str(sample.key_expr))
        if parsed:
            liveliness_events.put((*parsed, sample.kind == zenoh.SampleKind.PUT))

    clocks = ClockOffsets()
    clock_log = RateLimitedLog(service.log, interval=30.0)
    ahead_tol, behind_tol = CLOCK_WARN_SHARE * config.window_after, CLOCK_WARN_SHARE * config.window_before

    token_sub = service.session.liveliness().declare_subscriber(keys.alive("*", "*"), on_token, history=True)
    service.on_close(token_sub.undeclare)

    # A transcript is stamped at the utterance's end and published after recognition (0.3-1.2 s later): that
    # delay reads as a clock behind, so a source of transcripts is only ever warned about for running ahead.
    delayed_sources: set[str] = set()

    def handler(feed, delayed: bool = False):
        def handle(d: Delivery) -> None:
            if delayed:
                delayed_sources.add(d.sample.source)
            service.log.debug("in %s %.3f", d.key, d.sample.stamp)
            clocks.add(d.sample.source, d.sample.stamp, d.zenoh_time, d.received_at)
            emit(feed(d.key, d.sample, d.received_at))

        return handle

    service.subscribe_input("transcript", handler(core.on_transcript, delayed=True))
    service.subscribe_input("objects", handler(core.on_detections))
    service.subscribe_input("hands", handler(core.on_hands))
    service.subscribe_input("event", handler(core.on_gesture_event))
    service.subscribe_input("bodies", handler(core.on_bodies))  # which way the speaker faces
    service.subscribe_input("persons", handler(core.on_persons))  # people in view: "bring it to me"

    last_clock_report = [0.0]

    def report_clocks(now: float) -> None:
        if now - last_clock_report[0] < 1.0:
            return
        last_clock_report[0] = now
        for source in clocks.expire(now):
            service.counters.set(f"clock_offset_ms:{source}", None)
            delayed_sources.discard(source)
        for source, offset in clocks.offsets().items():
            service.counters.set(f"clock_offset_ms:{source}", round(offset * 1000))
            verdict = clock_verdict(offset, ahead_tol, behind_tol)
            if verdict == "ahead" or (verdict == "behind" and source not in delayed_sources):
                clock_log.warn(
                    f"clock:{source}",
                    f"{source}'s stamps run {abs(offset) * 1000:.0f} ms {verdict} of "
                    f"this machine's clock (tolerated: {ahead_tol * 1000:.0f} ms ahead, "
                    f"{behind_tol * 1000:.0f} ms behind): its words, points and detections are joined "
                    f"at the wrong moment. Keep the hosts in step with chrony or PTP "
                    f"(docs/foundation.md); `hri stats fusion` shows every source's offset",
                )

    def tick() -> None:
        while True:
            try:
                service_name, instance, present = liveliness_events.get_nowait()
            except queue.Empty:
                break
            core.on_liveliness(service_name, instance, present)
            if not present:  # a restarted instance starts a new estimate
                clocks.forget(f"{service_name}/{instance}")
                service.counters.set(f"clock_offset_ms:{service_name}/{instance}", None)
        now = time.time()
        report_clocks(now)
        emit(core.tick(now))

    service.log.info(
        "fusion: window [start-%.2f, end+%.2f] s, max wait %.2f s, %s weights%s",
        config.window_before,
        config.window_after,
        config.max_wait,
        config.weights,
        ", fallback to the most confident detection" if config.fallback_most_confident else "",
    )
    main_exit(service.run(tick=tick, tick_interval=0.02))


if __name__ == "__main__":
    main()
