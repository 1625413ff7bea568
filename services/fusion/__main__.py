"""Process shell of the fusion service: speech + vision + gesture -> FusedCommand / Clarification."""

from __future__ import annotations

import queue
import time

import zenoh

from common.runner import Delivery, Service, main_exit, service_parser
from common.schema import Bodies, Clarification, Detections, FusedCommand, GestureEvent, Hands, Transcript
from services.fusion.core import Config, FusionCore
from services.fusion.outputs import Output

EPILOG = """\
examples:
  hri-fusion                                   # adaptive weights, defaults below
  hri-fusion --weights fixed                   # constant modality weights (for comparison)
  hri-fusion --window-before 1.5 --max-wait 0.8
  hri echo 'hri/fusion/**'                     # watch its commands and questions

defaults: window [start - 1.0 s, end + 0.3 s] of source time, decide when every live modality's
latest stamp has passed the window end or 0.5 s (wall) after the transcript arrived; a clarification
stays open 10 s; a modality is live while its service's liveliness token exists or it sent a sample
in the last 2 s.
"""


def positive(text: str) -> float:
    value = float(text)
    if value < 0:
        raise ValueError(text)
    return value


def main(argv: list[str] | None = None) -> None:
    defaults = Config()
    parser = service_parser("fusion", "Join speech, vision and gesture on source time and publish grounded "
                                      "commands (FusedCommand) and questions (Clarification).", EPILOG)
    parser.add_argument("--window-before", type=positive, default=defaults.window_before, metavar="S",
                        help=f"seconds before the utterance start searched for gestures/objects "
                             f"(default {defaults.window_before})")
    parser.add_argument("--window-after", type=positive, default=defaults.window_after, metavar="S",
                        help=f"seconds after the utterance end (default {defaults.window_after})")
    parser.add_argument("--max-wait", type=positive, default=defaults.max_wait, metavar="S",
                        help=f"wall seconds after a transcript arrives before deciding with what is there "
                             f"(default {defaults.max_wait})")
    parser.add_argument("--weights", choices=("adaptive", "fixed"), default=defaults.weights,
                        help="modality weights from each modality's evidence (adaptive, default) or constant")
    parser.add_argument("--fallback-most-confident", action="store_true",
                        help="when nothing matches the words, act on the most confident detection instead of "
                             "asking (off by default: acting on the wrong object is worse than asking)")
    parser.add_argument("--dialogue-timeout", type=positive, default=defaults.dialogue_timeout, metavar="S",
                        help=f"seconds a clarification question stays open for an answer "
                             f"(default {defaults.dialogue_timeout})")
    args = parser.parse_args(argv)

    service = Service("fusion", args)
    config = Config(window_before=args.window_before, window_after=args.window_after, max_wait=args.max_wait,
                    weights=args.weights, fallback_most_confident=args.fallback_most_confident,
                    dialogue_timeout=args.dialogue_timeout)
    core = FusionCore(config, service.source, count=service.counters.add, log=service.log)
    if not service.connect():
        main_exit(0)
    keys = service.keys
    assert service.session is not None
    command_key, clarification_key = keys.command(), keys.clarification()

    def emit(outputs: list[Output]) -> None:
        for out in outputs:
            sample = out.sample
            if isinstance(sample, FusedCommand):
                # stops go out at REAL_TIME priority, express; everything is BLOCK (never dropped)
                service.publish(command_key, sample, lossless=True, realtime=out.realtime)
                service.log.info("command %s %s%s: %s", sample.id, sample.intent,
                                 f" -> {sample.target.id}" if sample.target else "", sample.explanation)
            elif isinstance(sample, Clarification):
                service.publish(clarification_key, sample, lossless=True)
                service.log.info("clarification %s (%s): %s", sample.id, sample.reason, sample.question)

    # Liveliness callbacks run on zenoh threads; the core belongs to the worker: hand over via a queue.
    liveliness_events: queue.SimpleQueue[tuple[str, str, bool]] = queue.SimpleQueue()

    def on_token(sample: zenoh.Sample) -> None:
        parsed = keys.parse_alive(str(sample.key_expr))
        if parsed:
            liveliness_events.put((*parsed, sample.kind == zenoh.SampleKind.PUT))

    token_sub = service.session.liveliness().declare_subscriber(keys.alive("*", "*"), on_token, history=True)
    service.on_close(token_sub.undeclare)

    def handler(feed):
        def handle(d: Delivery) -> None:
            service.log.debug("in %s %.3f", d.key, d.sample.stamp)
            emit(feed(d.key, d.sample, d.received_at))
        return handle

    service.subscribe(keys.transcript("*"), Transcript, handler(core.on_transcript), maxlen=200)
    service.subscribe(keys.objects("*"), Detections, handler(core.on_detections), maxlen=300)
    service.subscribe(keys.hands("*"), Hands, handler(core.on_hands), maxlen=600)
    service.subscribe(keys.gesture_event("*"), GestureEvent, handler(core.on_gesture_event), maxlen=200)
    service.subscribe(keys.bodies("*"), Bodies, handler(core.on_bodies), maxlen=50)  # which way the speaker faces

    def tick() -> None:
        while True:
            try:
                core.on_liveliness(*liveliness_events.get_nowait())
            except queue.Empty:
                break
        emit(core.tick(time.time()))

    service.log.info("fusion: window [start-%.2f, end+%.2f] s, max wait %.2f s, %s weights%s", config.window_before,
                     config.window_after, config.max_wait, config.weights,
                     ", fallback to the most confident detection" if config.fallback_most_confident else "")
    main_exit(service.run(tick=tick, tick_interval=0.02))


if __name__ == "__main__":
    main()
