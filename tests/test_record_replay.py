"""`hri record` / `hri replay`: the MCAP core on its own, then real round trips over Zenoh."""

from __future__ import annotations

import io
import json
import threading
import time

import mcap.reader
import msgpack
import pytest
from mcap.reader import make_reader

from common.codec import decode, encode
from common.keys import Keys
from common.schema import DetectedObject, Detections, GestureEvent, ImageQuality, Ray, Sample, Transcript
from hri.cli import make_transcript
from hri.recording import NS, Progress, ReplayClock, SessionReader, SessionWriter, raw_payload
from testkit.examples import example_key
from testkit.harness import Client

KEYS = Keys("hri")
T0 = 1_790_000_000.0


def detections(stamp: float, cam: str = "cam0") -> Detections:
    return Detections(
        stamp=stamp,
        source="test/vision",
        seq=1,
        cam=cam,
        width=640,
        height=480,
        objects=[
            DetectedObject(id="o1", label="cup", color="red", score=0.9, bbox=[10, 20, 60, 80], center=[40, 60]),
            DetectedObject(id="o2", label="cup", color="blue", score=0.8, bbox=[300, 20, 60, 80], center=[330, 60]),
        ],
        quality=ImageQuality(brightness=0.5, contrast=0.5, sharpness=0.8),
    )


def pointing(stamp: float, cam: str = "cam0") -> GestureEvent:
    return GestureEvent(
        stamp=stamp,
        source="test/gesture",
        cam=cam,
        width=640,
        height=480,
        gesture="point",
        phase="start",
        start=stamp - 0.2,
        end=stamp,
        score=0.9,
        hand="right",
        ray=Ray(origin=[500, 400], direction=[-0.6, -0.8]),
    )


def said(text: str, stamp: float) -> Transcript:
    return make_transcript(text, mic="kbd", end=stamp, confidence=0.95, source="test/speech")


# ---------------------------------------------------------------------------
# The functional core: no zenoh, no processes
# ---------------------------------------------------------------------------
def test_writer_makes_one_raw_sample_channel_per_key_with_stamp_as_publish_time(tmp_path):
    path = tmp_path / "core.mcap"
    contract = [
        (KEYS.transcript("kbd"), encode(said("pick up the red cup", T0))),
        (KEYS.objects("cam0"), encode(detections(T0 + 0.1))),
        (KEYS.transcript("kbd"), encode(said("stop", T0 + 0.5))),
    ]
    outside = [
        (KEYS.transcript("kbd"), msgpack.packb({"text": "no envelope"})),  # contract key, invalid sample
        ("hri/test/raw", b"\x01\x02 not msgpack"),
    ]  # key outside the contract
    received = [int((T0 + 1 + i) * NS) for i in range(5)]
    with open(path, "wb") as f:
        writer = SessionWriter(f, KEYS, metadata={"keyexpr": "hri/**"}, viewers=False)  # the raw layout
        for (key, payload), at in zip(contract + outside, received):
            writer.add(key, payload, at)
        writer.finish()

    with open(path, "rb") as f:  # read back with the mcap library itself, not our reader
        reader = make_reader(f)
        summary = reader.get_summary()
        assert summary is not None and summary.statistics.message_count == 5
        channels = {c.topic: c for c in summary.channels.values()}
        assert set(channels) == {"hri/speech/kbd/transcript", "hri/vision/cam0/objects", "hri/test/raw"}
        assert {c.message_encoding for c in channels.values()} == {"protobuf"}
        assert channels["hri/speech/kbd/transcript"].metadata["schema"] == "Transcript"
        assert channels["hri/vision/cam0/objects"].metadata["schema"] == "Detections"
        assert channels["hri/test/raw"].metadata["schema"] == ""
        # every raw channel points at the one RawSample schema record: the payload in a protobuf bytes field
        (record,) = summary.schemas.values()
        assert {c.schema_id for c in channels.values()} == {record.id}
        assert (record.name, record.encoding) == ("hri_fusion.RawSample", "protobuf")
        got = [
            (ch.topic, raw_payload(sc, ch, m.data), m.log_time, m.publish_time, m.sequence)
            for sc, ch, m in reader.iter_messages()
        ]
        assert [m.name for m in reader.iter_metadata()] == ["hri.record"]
    stamps = [T0, T0 + 0.1, T0 + 0.5]
    expected = [
        (key, payload, at, int(round(stamp * NS))) for (key, payload), at, stamp in zip(contract, received, stamps)
    ]
    expected += [(key, payload, at, at) for (key, payload), at in zip(outside, received[3:])]
    assert [g[:4] for g in got] == expected
    assert [g[4] for g in got] == [1, 1, 2, 3, 1]  # per-channel sequence
    assert writer.tally["hri/speech/kbd/transcript"].not_contract == 1


# what Foxglove decodes: message encoding -> the schema encoding it reads the schema as (it also reads ros2msg/CDR,
# flatbuffer, cbor and schemaless JSON; a recording uses these two); msgpack is not among them
FOXGLOVE_DECODES = {"protobuf": "protobuf", "json": "jsonschema"}


def test_every_channel_decodes_in_foxglove_and_replays_the_payloads_byte_for_byte(tmp_path):
    foxglove_protobuf = pytest.importorskip("mcap_protobuf.decoder", reason="mcap-protobuf-support is not installed")
    jsonschema = pytest.importorskip("jsonschema")
    pytest.importorskip("foxglove", reason="foxglove-sdk (the viewer channels) is not installed")
    from testkit.examples import examples

    sent = [(example_key(sample), encode(sample)) for sample in examples()]
    sent += [
        (KEYS.transcript("kbd"), msgpack.packb({"text": "no envelope"})),  # a contract key, an invalid sample
        ("hri/test/raw", b"\x0a\x02 not msgpack, nor protobuf"),
        ("hri/test/empty", b""),
    ]
    path = tmp_path / "session.mcap"
    with open(path, "wb") as f:
        writer = SessionWriter(f, KEYS, viewers=True)
        for i, (key, payload) in enumerate(sent):
            writer.add(key, payload, int((T0 + 0.01 * i) * NS))
        writer.finish()

    decoders = foxglove_protobuf.DecoderFactory()
    raw_back = []
    with open(path, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        assert summary is not None
        for channel in summary.channels.values():  # each channel's encoding and schema, as Foxglove reads them
            schema = summary.schemas[channel.schema_id]
            assert FOXGLOVE_DECODES.get(channel.message_encoding) == schema.encoding, (channel.topic, schema.name)
            if schema.encoding == "jsonschema":
                jsonschema.Draft202012Validator.check_schema(json.loads(schema.data))
            else:
                assert decoders.decoder_for("protobuf", schema) is not None, schema.name
        assert len(summary.channels) > 23  # the raw channels and the viewer channels beside them
        for schema, channel, message in reader.iter_messages(log_time_order=True):  # every message decodes
            if channel.message_encoding == "json":
                jsonschema.validate(json.loads(message.data), json.loads(schema.data))
                continue
            decoded = decoders.decoder_for("protobuf", schema)(message.data)
            if schema.name == "hri_fusion.RawSample":  # Foxglove shows its `data`: the payload as received
                raw_back.append((channel.topic, decoded.data))
    assert raw_back == sent

    replayed = SessionReader(path)  # what `hri replay` sends
    assert [(m.key, m.payload) for m in replayed.messages()] == sent and not replayed.skipped_encodings
    replayed.close()


def test_reader_filters_keys_keeps_receive_order_and_survives_a_cut_off_file(tmp_path):
    keys = [KEYS.transcript("kbd"), KEYS.objects("cam0"), KEYS.gesture_event("cam0")]
    payloads = []
    path = tmp_path / "cut.mcap"
    with open(path, "wb") as f:
        writer = SessionWriter(f, KEYS, chunk_size=2048)  # several chunks, so a cut keeps some
        for i in range(60):
            key = keys[i % 3]
            sample = {0: said(f"stop {i}", T0 + i), 1: detections(T0 + i), 2: pointing(T0 + i)}[i % 3]
            payloads.append((key, encode(sample)))
            writer.add(key, payloads[-1][1], int((T0 + i) * NS))
        writer.finish()

    whole = SessionReader(path)
    assert whole.info.complete and whole.info.samples == 60 and whole.info.span_s == pytest.approx(59.0)
    assert [(m.key, m.payload) for m in whole.messages()] == payloads
    only_speech = list(whole.messages(lambda k: k.startswith("hri/speech/")))
    assert [(m.key, m.payload) for m in only_speech] == payloads[0::3]
    whole.close()

    data = path.read_bytes()
    with open(path, "rb") as f:
        chunks = mcap.reader.make_reader(f).get_summary().chunk_indexes
    # Cut in the middle of the chunked data (the header's schemas and the summary around it vary in size with the
    # contract): what a SIGKILLed recorder leaves behind.
    middle = (chunks[0].chunk_start_offset + chunks[-1].chunk_start_offset + chunks[-1].chunk_length) // 2
    cut = tmp_path / "killed.mcap"
    cut.write_bytes(data[:middle])
    partial = SessionReader(cut)
    got = [(m.key, m.payload) for m in partial.messages()]
    assert not partial.info.complete and partial.damaged
    assert 0 < len(got) < 60 and got == payloads[: len(got)]
    partial.close()


def test_replay_clock_scales_gaps_and_catches_up_when_late():
    now = [100.0]
    clock = ReplayClock(speed=2.0, now=lambda: now[0])
    assert clock.wait_for(5 * NS) == 0.0  # the first message anchors the schedule
    assert clock.wait_for(7 * NS) == pytest.approx(1.0)  # 2 s recorded at x2
    now[0] += 3.0  # we were late: due times stay absolute
    assert clock.wait_for(7 * NS) == 0.0
    assert clock.wait_for(13 * NS) == pytest.approx(1.0)  # due at 100 + 4, now 103
    assert ReplayClock(speed=0).wait_for(10**12) == 0.0
    with pytest.raises(ValueError):
        ReplayClock(speed=-1)


def test_progress_prints_about_once_per_interval():
    now = [0.0]
    out = io.StringIO()
    progress = Progress(out, interval=1.0, now=lambda: now[0])
    assert not progress.due()
    now[0] = 1.2
    assert progress.due()
    progress.show("recording: 3 samples")
    assert not progress.due()
    progress.end("recorded: 3 samples")
    assert out.getvalue() == "recording: 3 samples\nrecorded: 3 samples\n"


def test_replay_explains_a_missing_or_foreign_file(tmp_path):
    from hri.recording import RecordingError

    with pytest.raises(RecordingError, match="cannot open"):
        SessionReader(tmp_path / "nope.mcap")
    junk = tmp_path / "junk.mcap"
    junk.write_bytes(b"this is not an mcap file at all")
    with pytest.raises(RecordingError, match="not an MCAP file"):
        SessionReader(junk)


# ---------------------------------------------------------------------------
# Real processes over Zenoh
# ---------------------------------------------------------------------------
def wait_for_text(proc, text: str, timeout: float = 30.0) -> None:
    deadline = time.monotonic() + timeout
    while text not in proc.output():
        assert proc.alive(), f"{proc.name} exited early:\n{proc.output()}"
        assert time.monotonic() < deadline, f"{proc.name} never printed {text!r}:\n{proc.output()}"
        time.sleep(0.1)


def wait_matched(client: Client, keys: list[str], timeout: float = 15.0) -> None:
    """Block until the router knows a subscriber for each key (samples sent earlier would be lost)."""
    pubs = [client.session.declare_publisher(k) for k in keys]
    deadline = time.monotonic() + timeout
    try:
        while not all(p.matching_status.matching for p in pubs):  # type: ignore[attr-defined]  # zenoh's stub types matching_status as bool; it is a MatchingStatus
            assert time.monotonic() < deadline, f"no subscriber matched {keys} within {timeout} s"
            time.sleep(0.05)
    finally:
        for p in pubs:
            p.undeclare()


class RawTap:
    """Every payload on a key expression, byte for byte, with its arrival time."""

    def __init__(self, client: Client, keyexpr: str):
        self.items: list[tuple[str, bytes, float, str]] = []
        self._lock = threading.Lock()
        self._sub = client.session.declare_subscriber(keyexpr, self._on)

    def _on(self, s) -> None:
        with self._lock:
            self.items.append((str(s.key_expr), s.payload.to_bytes(), time.monotonic(), str(s.encoding)))

    def wait(self, n: int, timeout: float = 30.0) -> list[tuple[str, bytes, float, str]]:
        deadline = time.monotonic() + timeout
        while len(self.items) < n and time.monotonic() < deadline:
            time.sleep(0.05)
        time.sleep(0.3)  # anything extra (which would be a bug) has time to show up
        with self._lock:
            return list(self.items)

    def clear(self) -> None:
        with self._lock:
            self.items.clear()


GAP = 0.5  # seconds between published samples: big against scheduling jitter
# How much earlier than recorded a replayed sample may seem to arrive: the first sample's delivery delay
# (loopback, a few ms when idle). 0.15 s failed once under load average 5 as a per-gap bound; as a bound on
# the offset from the first sample only that one delay counts. 0.25 s stays half a GAP, so a skipped wait fails.
JITTER_S = 0.25


@pytest.mark.integration
def test_record_then_replay_round_trip(group, tmp_path):
    group.router()
    path = tmp_path / "session.mcap"
    recorder = group.start("record", "hri.cli", "record", "-o", str(path), "hri/**")
    wait_for_text(recorder, "recording 'hri/**'")
    client = Client(group.endpoint)
    try:
        token = client.session.liveliness().declare_token("hri/alive/test/recording")  # not data: not recorded
        now = time.time()
        sent: list[tuple[str, Sample]] = [
            (KEYS.transcript("kbd"), said("pick up the red cup", now)),
            (KEYS.objects("cam0"), detections(now + 0.01)),
            (KEYS.gesture_event("cam0"), pointing(now + 0.02)),
            (KEYS.transcript("kbd"), said("stop", now + 0.03)),
        ]
        wait_matched(client, [k for k, _ in sent] + ["hri/test/raw"])
        before_ns = time.time_ns()
        for key, sample in sent:
            client.publish(key, sample)
            time.sleep(GAP)
        client.put_raw("hri/test/raw", b"\xc1 outside the contract")
        wait_for_text(recorder, "recording: 5 samples")  # its progress line (once a second): all five are written
        after_ns = time.time_ns()
        code, _ = recorder.terminate(timeout=5.0)
        assert code == 0, recorder.output()
        assert "recorded: 5 samples" in recorder.output()
        token.undeclare()

        # -- the file, read with the mcap library
        with open(path, "rb") as f:
            reader = make_reader(f)
            summary = reader.get_summary()
            assert summary is not None, "no summary: the recorder did not finish the file on SIGTERM"
            raw = {c.topic: c.message_encoding for c in summary.channels.values() if "hri.viewer" not in c.metadata}
            assert raw == {
                KEYS.transcript("kbd"): "protobuf",
                KEYS.objects("cam0"): "protobuf",
                KEYS.gesture_event("cam0"): "protobuf",
                "hri/test/raw": "protobuf",
            }
            # beside them, the copies Foxglove decodes (tests/test_viewers.py decodes every message of them)
            viewer = {c.topic for c in summary.channels.values() if "hri.viewer" in c.metadata}
            assert {"/" + KEYS.transcript("kbd"), "/" + KEYS.objects("cam0") + "/annotations", "/hri/log"} <= viewer
            recorded = [
                (ch.topic, raw_payload(sc, ch, m.data), m.log_time, m.publish_time)
                for sc, ch, m in reader.iter_messages()
                if "hri.viewer" not in ch.metadata
            ]
        expected = [(k, encode(s)) for k, s in sent] + [("hri/test/raw", b"\xc1 outside the contract")]
        assert [(k, d) for k, d, _, _ in recorded] == expected
        log_times = [t for _, _, t, _ in recorded]
        assert before_ns <= log_times[0] and log_times[-1] <= after_ns and log_times == sorted(log_times)
        assert [p for _, _, _, p in recorded[:4]] == [int(round(s.stamp * NS)) for _, s in sent]
        assert recorded[4][3] == recorded[4][2]  # not a contract sample: publish time = receive time

        # -- replay at the original speed: same bytes, same order, same rhythm
        tap = RawTap(client, "hri/**")
        res = group.hri("replay", str(path), timeout=60)
        assert res.returncode == 0, res.stderr
        assert "replayed: 5 samples" in res.stderr
        got = tap.wait(5)
        assert [(k, d) for k, d, _, _ in got] == expected
        assert {e for _, _, _, e in got} == {"application/msgpack"}
        # The replay's schedule is absolute, anchored at its first send: no sample may arrive earlier after the
        # first than it was recorded after the first, less the first one's own delivery delay (JITTER_S). Checked
        # per sample from the first, not per gap: one late sample (load) shortens the next gap but not this.
        # A replay that skipped any one wait (GAP = 0.5 s) still fails.
        recorded_offsets = [(t - log_times[0]) / NS for t in log_times]
        arrival_offsets = [g[2] - got[0][2] for g in got]
        for recorded_at, arrived_at in zip(recorded_offsets, arrival_offsets):
            assert arrived_at >= recorded_at - JITTER_S, (recorded_offsets, arrival_offsets)
        assert arrival_offsets[-1] <= recorded_offsets[-1] + 2.0, (recorded_offsets, arrival_offsets)

        # -- --only: speech alone, four times faster
        tap.clear()
        res = group.hri("replay", str(path), "--only", "hri/speech/**", "--speed", "4", timeout=60)
        assert res.returncode == 0, res.stderr
        got = tap.wait(2)
        assert [(k, d) for k, d, _, _ in got] == [e for e in expected if e[0].startswith("hri/speech/")]
        speech_gap = (log_times[3] - log_times[0]) / NS  # ~3 * GAP recorded
        assert speech_gap / 4 - JITTER_S <= got[1][2] - got[0][2] < speech_gap * 0.75

        # -- --speed 0 --loop: back to back, over and over until SIGTERM
        tap.clear()
        looper = group.start(
            "replay", "hri.cli", "replay", str(path), "--only", "hri/vision/*/objects", "--speed", "0", "--loop"
        )
        got = tap.wait(3)
        code, _ = looper.terminate(timeout=5.0)
        assert code == 0, looper.output()
        assert len(got) >= 3 and {(k, d) for k, d, _, _ in got} == {expected[1]}
    finally:
        client.close()


@pytest.mark.integration
def test_record_stops_by_itself_after_count_or_duration(group, tmp_path):
    group.router()
    counted, timed = tmp_path / "count.mcap", tmp_path / "duration.mcap"
    by_count = group.start("record-count", "hri.cli", "record", "-o", str(counted), "hri/speech/**", "--count", "2")
    wait_for_text(by_count, "recording")
    by_time = group.start("record-duration", "hri.cli", "record", "-o", str(timed), "--duration", "3")
    wait_for_text(by_time, "recording")
    client = Client(group.endpoint)
    try:
        wait_matched(client, [KEYS.transcript("kbd")])
        for i in range(4):
            client.publish(KEYS.transcript("kbd"), said(f"stop {i}", time.time()))
            time.sleep(0.1)
        for proc in (by_count, by_time):
            proc.popen.wait(30)
            assert proc.popen.returncode == 0, proc.output()
    finally:
        client.close()
    reader = SessionReader(counted)
    assert reader.info.complete and reader.info.keys == {KEYS.transcript("kbd"): 2}
    texts = [msgpack.unpackb(m.payload)["text"] for m in reader.messages()]
    assert texts == ["stop 0", "stop 1"]
    reader.close()
    reader = SessionReader(timed)
    assert reader.info.complete and reader.info.keys.get(KEYS.transcript("kbd")) == 4
    reader.close()


@pytest.mark.integration
def test_record_refuses_to_overwrite_and_replay_rejects_bad_input(group, tmp_path):
    existing = tmp_path / "taken.mcap"
    existing.write_bytes(b"precious")
    res = group.hri("record", "-o", str(existing), "hri/**")
    assert res.returncode == 2 and "--force" in res.stderr and existing.read_bytes() == b"precious"
    res = group.hri("replay", str(tmp_path / "missing.mcap"))
    assert res.returncode == 2 and "cannot open" in res.stderr
    empty = tmp_path / "empty.mcap"
    with open(empty, "wb") as f:
        SessionWriter(f, KEYS).finish()
    res = group.hri("replay", str(empty))
    assert res.returncode == 1 and "nothing to replay" in res.stderr
    res = group.hri("replay", str(empty), "--only", "hri//bad")
    assert res.returncode == 2 and "not a valid key expression" in res.stderr


# ---------------------------------------------------------------------------
# The point of it all: a recorded session replayed into a fresh fusion service
# ---------------------------------------------------------------------------
REPLAYED_SCENARIOS = ("colour: the red cup", "pointing: that cup", "follow-up: the red one", "open palm: stop at once")
INPUT_KEYS = [KEYS.transcript("mic0"), KEYS.objects("cam0"), KEYS.hands("cam0"), KEYS.gesture_event("cam0")]


def outcome(sample) -> tuple:
    """What a fused output decides (the volatile parts — stamps, explanation wording — left out)."""
    from common.schema import Clarification

    if isinstance(sample, Clarification):
        return ("clarification", sample.id, sample.reason, sorted(c.id for c in sample.candidates))
    return (
        "command",
        sample.id,
        sample.intent,
        sample.target.id if sample.target else None,
        sample.location is not None,
    )


def warm_up_fusion(client: Client, timeout: float = 30.0) -> None:
    """Inputs that decide nothing (no objects, no hands), until fusion counts them: its routes exist."""
    from testkit.scenarios import BASE_STAMP, hands, see

    deadline, round_ = time.monotonic() + timeout, 0
    while time.monotonic() < deadline:
        before = client.stats("fusion")["received"]
        for step in (see(0.0, []), hands(0.0)):
            client.publish(*step.build(BASE_STAMP - 10_000 + round_))
        time.sleep(0.3)
        if client.stats("fusion")["received"] - before >= 2:
            return
        round_ += 1
    raise AssertionError("fusion never received the warm-up samples")


@pytest.mark.integration
def test_replaying_a_recorded_session_into_a_fresh_fusion_reproduces_its_commands(group, tmp_path):
    from common.schema import Clarification, FusedCommand
    from testkit.scenarios import BASE_STAMP, SCENARIO_SPACING, check, say, see
    from testkit.scenarios.suite import SCENARIOS

    by_name = {s.name: s for s in SCENARIOS}
    missing = [n for n in REPLAYED_SCENARIOS if n not in by_name]
    assert not missing, f"scenarios {missing} are gone from testkit/scenarios/suite.py; pick others"
    chosen = [by_name[n] for n in REPLAYED_SCENARIOS]
    base0 = BASE_STAMP + 500 * SCENARIO_SPACING  # far from the warm-up stamps
    sentinel_at = 25.0  # as in tests/test_fusion_scenarios.py: after every step, inside fusion's horizon

    group.router()
    path = tmp_path / "fusion-session.mcap"
    recorder = group.start("record", "hri.cli", "record", "-o", str(path), "hri/**")
    wait_for_text(recorder, "recording 'hri/**'")
    client = Client(group.endpoint)
    try:
        wait_matched(client, INPUT_KEYS)  # only the recorder subscribes so far: its route exists
        outputs = client.collect("hri/fusion/**")
        fusion = group.service("fusion")
        client.wait_alive("fusion")
        warm_up_fusion(client)

        def decided(since: int, base: float) -> list:
            """Wait for the sentinel's command of the scenario at `base`; return that scenario's outputs."""

            def is_sentinel(key: str, s: object) -> bool:
                return isinstance(s, FusedCommand) and s.stamp == base + sentinel_at

            earlier = sum(1 for item in outputs.seen[:since] if is_sentinel(*item))  # A's, when B replays
            try:
                outputs.wait(earlier + 1, 30, where=is_sentinel)
            except TimeoutError as exc:
                raise AssertionError(
                    f"no answer to the sentinel at {base + sentinel_at}: {exc}\n{group.logs()}"
                ) from None
            outputs.drain(0.05)
            return [
                s
                for _, s in outputs.seen[since:]
                if isinstance(s, (FusedCommand, Clarification)) and base - 10 <= s.stamp < base + sentinel_at
            ]

        # -- live: the scenarios' inputs into fusion A, everything recorded
        live = []
        for i, scenario in enumerate(chosen):
            base = base0 + i * SCENARIO_SPACING
            since = len(outputs.seen)
            for key, sample in scenario.samples(base):
                client.publish(key, sample)
            for step in (see(sentinel_at + 1.0, []), say(sentinel_at - 1.0, sentinel_at, "hello", lag=0.0)):
                client.publish(*step.build(base))
            got = decided(since, base)
            assert not check(scenario, got), f"live fusion: {scenario.name}: {check(scenario, got)}"
            live.append([outcome(s) for s in got])
        code, _ = recorder.terminate(timeout=5.0)
        assert code == 0, recorder.output()
        code, _ = fusion.terminate(timeout=5.0)
        assert code == 0, fusion.output()

        # the recording holds A's answers too, exactly as the collector received them
        reader = SessionReader(path)
        in_file = [
            decode(m.payload, KEYS.schema_for(m.key)) for m in reader.messages(lambda k: k.startswith("hri/fusion/"))
        ]
        reader.close()
        answered_live = [outcome(s) for _, s in outputs.seen if s.stamp >= base0 - 10]
        assert sorted(outcome(s) for s in in_file if s.stamp >= base0 - 10) == sorted(answered_live)

        # -- replay only the inputs into a fresh fusion B
        fresh = group.service("fusion")
        client.wait_alive("fusion")
        wait_matched(client, INPUT_KEYS)  # A and the recorder are gone: this is B's route
        since = len(outputs.seen)
        res = group.hri(
            "replay",
            str(path),
            "--only",
            "hri/speech/**",
            "--only",
            "hri/vision/**",
            "--only",
            "hri/gesture/**",
            timeout=180,
        )
        assert res.returncode == 0, res.stderr
        replayed = []
        for i in range(len(chosen)):
            base = base0 + i * SCENARIO_SPACING
            got = decided(since, base)
            replayed.append([outcome(s) for s in got])
        assert replayed == live, f"live {live}\nreplayed {replayed}\n{group.logs()}"
        assert sum(1 for _, s in outputs.seen[since:] if s.stamp >= base0 - 10) == len(answered_live), (
            "the replay made fusion B publish more or fewer outputs than A did live"
        )
        assert fresh.alive()
    finally:
        client.close()
