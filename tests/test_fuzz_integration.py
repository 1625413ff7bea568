"""10,000 malformed samples over every service's input keys: every service survives, counts what it rejected
by reason, keeps its memory bounded and still serves fresh valid input within a second.

Prints the figures written in docs/foundation.md (samples thrown, rejected by reason, time to serve fresh
input afterwards, peak memory per service)."""

from __future__ import annotations

import collections
import json
import time
from pathlib import Path

import cv2
import pytest

from common.schema import (
    AudioChunk,
    DetectedObject,
    Detections,
    Face,
    Faces,
    Frame,
    GestureEvent,
    Hand,
    Hands,
    ImageQuality,
    Ray,
    Sample,
)
from hri.cli import make_transcript
from testkit.fuzz import Fuzzer, image_bomb
from testkit.harness import DATA, Client
from testkit.images import read_image

pytestmark = pytest.mark.integration

SAMPLES = 10_000
SERVICES = ("vision", "gesture", "speech", "fusion")
PHOTO = DATA / "images" / "tabletop" / "smarties.png"
FRESH_WITHIN_S = 1.0  # measured 0.01-0.11 s under load (docs/foundation.md): a backlog, not jitter, fails
MAX_GROWTH_MB = 150  # peak RSS over the RSS after warm-up: bounded, not growing with the flood (measured 32-43 MB)


def jpeg_frame(seq: int, stamp: float) -> Frame:
    img = read_image(str(PHOTO))
    return Frame(
        stamp=stamp,
        source="test/cam",
        seq=seq,
        cam="cam0",
        width=img.shape[1],
        height=img.shape[0],
        encoding="jpeg",
        data=cv2.imencode(".jpg", img)[1].tobytes(),
    )


def valid_inputs(now: float) -> dict[str, Sample]:
    obj = DetectedObject(id="o1", label="candy", color="red", score=0.9, bbox=[10, 10, 20, 20], center=[20, 20])
    ray = Ray(origin=[100.0, 100.0], direction=[1.0, 0.0], confidence=0.9)
    hand = Hand(hand="right", score=0.9, landmarks=[[float(i), float(i)] for i in range(21)], gesture="point", ray=ray)
    return {
        "hri/camera/cam0/frame": jpeg_frame(0, now),
        "hri/audio/mic0/pcm": AudioChunk(
            stamp=now, source="test/mic", mic="mic0", rate=16000, channels=1, format="s16le", data=b"\0\0" * 320
        ),
        "hri/speech/kbd/transcript": make_transcript(
            "pick up the red candy", mic="kbd", end=now, confidence=1.0, source="test/kbd"
        ),
        "hri/vision/cam0/objects": Detections(
            stamp=now,
            source="test/v",
            seq=0,
            cam="cam0",
            width=640,
            height=480,
            objects=[obj],
            quality=ImageQuality(brightness=0.5, contrast=0.5, sharpness=0.5),
        ),
        "hri/gesture/cam0/hands": Hands(
            stamp=now, source="test/g", seq=0, cam="cam0", width=640, height=480, hands=[hand]
        ),
        "hri/gesture/cam0/faces": Faces(
            stamp=now,
            source="test/g",
            seq=0,
            cam="cam0",
            width=640,
            height=480,
            faces=[Face(id="cam0/face-1", bbox=[100, 80, 90, 110], score=0.5, mouth_open=0.1, yaw=5.0, pitch=0.0)],
        ),
        "hri/gesture/cam0/event": GestureEvent(
            stamp=now,
            source="test/g",
            cam="cam0",
            width=640,
            height=480,
            gesture="point",
            phase="start",
            start=now - 0.2,
            end=now,
            score=0.9,
            hand="right",
            ray=ray,
        ),
    }


CONSUMERS = {
    "hri/camera/cam0/frame": ("vision", "gesture"),
    "hri/audio/mic0/pcm": ("speech",),
    "hri/speech/kbd/transcript": ("fusion",),
    "hri/vision/cam0/objects": ("fusion",),
    "hri/gesture/cam0/hands": ("fusion",),
    "hri/gesture/cam0/event": ("fusion",),
    "hri/gesture/cam0/faces": ("fusion",),
}


def rss_mb(pid: int) -> tuple[float, float]:
    """(current, peak) resident memory of a process in MB."""
    fields = dict(line.split(":", 1) for line in Path(f"/proc/{pid}/status").read_text().splitlines() if ":" in line)
    return int(fields["VmRSS"].split()[0]) / 1024, int(fields["VmHWM"].split()[0]) / 1024


def wait_received(client: Client, service: str, n: int, timeout: float) -> dict:
    """The service's stats once it has received `n` samples. A stats query it leaves unanswered is a count not read
    yet: its queryable shares the Zenoh callback threads with the flood it is validating (on a loaded 2-core machine
    a query went unanswered for 2 s while gesture took in the flood), so only the deadline fails the wait."""
    deadline = time.monotonic() + timeout
    stats: dict | None = None
    while True:
        stats = answered_stats(client, service) or stats
        if stats is not None and stats["received"] >= n:
            return stats
        if time.monotonic() > deadline:
            raise AssertionError(f"{service} did not receive {n} samples in {timeout} s; its last stats: {stats}")
        time.sleep(0.2)


def answered_stats(client: Client, service: str) -> dict | None:
    """The service's stats, or None if it did not answer within 2 s."""
    try:
        return client.stats(service)
    except AssertionError:  # Client.stats: "did not answer a stats query"
        return None


def say_and_time(client: Client, transcripts, samples) -> float:
    """Send an utterance as 20 ms AudioChunks stamped now; seconds from its last chunk to its transcript."""
    t_audio = time.time()
    for off in range(0, len(samples), 320):
        client.publish(
            "hri/audio/mic0/pcm",
            AudioChunk(
                stamp=t_audio + off / 16000,
                source="test/mic",
                mic="mic0",
                rate=16000,
                channels=1,
                format="s16le",
                data=samples[off : off + 320].astype("<i2").tobytes(),
            ),
        )
    t0 = time.monotonic()
    transcripts.wait(1, timeout=30, where=lambda k, t: t.start >= t_audio - 0.1)
    transcripts.seen.clear()
    return time.monotonic() - t0


def flood(client: Client) -> tuple[collections.Counter[str], collections.Counter[str], float]:
    """SAMPLES malformed samples spread over every input key, plus one oversized payload per key: (how many of
    each kind were thrown, how many each service should receive, seconds it took)."""
    bomb = image_bomb()
    valid = valid_inputs(time.time())
    fuzzers = {key: Fuzzer(sample, seed=i, bomb=bomb) for i, (key, sample) in enumerate(valid.items())}
    thrown: collections.Counter[str] = collections.Counter()
    per_key = SAMPLES // len(fuzzers)
    t0 = time.monotonic()
    for key, fuzzer in fuzzers.items():
        payloads = list(fuzzer.payloads(per_key))
        if key != "hri/camera/cam0/frame":  # a 64 MiB frame only slows loopback; test_codec covers that cap
            payloads.append(("oversized", fuzzer.oversized()))
        for kind, payload in payloads:
            client.put_raw(key, payload)
            thrown[kind] += 1
    throw_s = time.monotonic() - t0
    expected: collections.Counter[str] = collections.Counter()
    for key in fuzzers:
        for name in CONSUMERS[key]:
            expected[name] += per_key + (key != "hri/camera/cam0/frame")
    return thrown, expected, throw_s


def test_ten_thousand_malformed_samples_blind_no_service(group, tmp_path):
    from testkit.synth import read_wav_int16, synthesize

    group.router()
    procs = {name: group.service(name, *(["--input", "zenoh"] if name == "speech" else [])) for name in SERVICES}
    client = Client(group.endpoint)
    figures: dict[str, dict] = {}
    try:
        for name in SERVICES:
            client.wait_alive(name, timeout=120)
        detections, hands = client.collect("hri/vision/cam0/objects"), client.collect("hri/gesture/cam0/hands")
        commands, transcripts = client.collect("hri/fusion/command"), client.collect("hri/speech/*/transcript")

        # warm-up: models loaded, one of everything served
        client.publish("hri/camera/cam0/frame", jpeg_frame(1, time.time()))
        detections.wait(1, timeout=60)
        hands.wait(1, timeout=60)
        client.publish(
            "hri/speech/kbd/transcript",
            make_transcript("stop", mic="kbd", end=time.time(), confidence=1.0, source="test/kbd"),
        )
        commands.wait(1, timeout=30)
        utterance = read_wav_int16(
            synthesize("bring me the yellow book", tmp_path / "cmd.wav", voice="en-us+f3", trail_silence=0.8)
        )
        normal_speech_s = say_and_time(client, transcripts, utterance)  # what recognition takes unflooded
        baseline = {name: rss_mb(procs[name].pid)[0] for name in SERVICES}
        received0 = {name: client.stats(name)["received"] for name in SERVICES}

        thrown, expected, throw_s = flood(client)
        for name in SERVICES:  # raises if a service does not get its share in time
            wait_received(client, name, received0[name] + expected[name], timeout=180)
        time.sleep(0.5)  # let the worker threads finish what passed validation

        # still serving fresh input within a second
        fresh: dict[str, float] = {}
        now = time.time()
        t0 = time.monotonic()
        client.publish("hri/camera/cam0/frame", jpeg_frame(99999, now))
        detections.wait(1, timeout=30, where=lambda k, s: s.seq == 99999)
        fresh["vision"] = time.monotonic() - t0
        hands.wait(1, timeout=30, where=lambda k, s: s.seq == 99999)
        fresh["gesture"] = time.monotonic() - t0
        stop = make_transcript("stop", mic="kbd", end=time.time(), confidence=1.0, source="test/kbd")
        t0 = time.monotonic()
        client.publish("hri/speech/kbd/transcript", stop)
        commands.wait(1, timeout=30, where=lambda k, c: c.inputs.get("speech") == stop.stamp)
        fresh["fusion"] = time.monotonic() - t0
        fresh["speech"] = say_and_time(client, transcripts, utterance)

        for name in SERVICES:
            st = client.stats(name)
            cur, peak = rss_mb(procs[name].pid)
            figures[name] = {
                "received": st["received"] - received0[name],
                "rejected": st["rejected"],
                "other": st["other"],
                "fresh_s": round(fresh[name], 3),
                "rss_after_warmup_mb": round(baseline[name], 1),
                "peak_rss_mb": round(peak, 1),
            }
        figures["speech"]["unflooded_s"] = round(normal_speech_s, 3)
        print(f"\nthrown {sum(thrown.values())} malformed samples in {throw_s:.1f} s: {dict(thrown)}")
        print(json.dumps(figures, indent=1))

        for name in SERVICES:
            assert procs[name].alive(), group.logs()
            f = figures[name]
            # measured 0.92-0.98 of what each service received (a fuzzed sample can be valid); margin 0.3
            assert sum(f["rejected"].values()) >= 0.6 * expected[name], (name, f)
            # speech: a second beyond what recognising the utterance takes when nothing floods it
            assert f["fresh_s"] <= FRESH_WITHIN_S + (normal_speech_s if name == "speech" else 0.0), (name, f)
            assert f["peak_rss_mb"] - f["rss_after_warmup_mb"] <= MAX_GROWTH_MB, (name, f)
        for name in ("vision", "gesture"):
            rejected = figures[name]["rejected"]
            for reason in (
                "not_msgpack",
                "not_a_map",
                "missing_field",
                "wrong_type",
                "not_finite",
                "future_stamp",
                "out_of_order",
                "bad_value",
                "oversized",
            ):
                assert rejected.get(reason, 0) >= 1, (name, reason, rejected)
            assert figures[name]["other"].get("undecodable", 0) + rejected.get("undecodable", 0) >= 1, figures[name]
        for name in ("speech", "fusion"):
            for reason in (
                "not_msgpack",
                "not_a_map",
                "missing_field",
                "wrong_type",
                "not_finite",
                "future_stamp",
                "oversized",
            ):
                assert figures[name]["rejected"].get(reason, 0) >= 1, (name, reason, figures[name])
        assert figures["speech"]["rejected"].get("out_of_order", 0) >= 1
    finally:
        client.close()
