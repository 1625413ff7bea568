"""Malformed samples on a service's input keys are counted in its stats, and the service keeps working."""

import time
from typing import Any, Callable

import cv2
import msgpack
import pytest

from common.codec import encode
from common.schema import Frame
from hri.cli import make_transcript
from testkit.harness import DATA, Client, requires_services
from testkit.images import read_image

pytestmark = pytest.mark.integration

PHOTO = DATA / "images" / "tabletop" / "smarties.png"


def real_frame(seq: int, stamp: float) -> Frame:
    img = read_image(str(PHOTO))
    data = cv2.imencode(".jpg", img)[1].tobytes()
    return Frame(
        stamp=stamp,
        source="test/cam",
        seq=seq,
        cam="cam0",
        width=img.shape[1],
        height=img.shape[0],
        encoding="jpeg",
        data=data,
    )


def bad_payloads(valid: bytes, schema_cap: int) -> dict[str, bytes]:
    as_map = msgpack.unpackb(valid)
    nan_stamp = msgpack.packb({**as_map, "stamp": float("nan")})
    missing = msgpack.packb({k: v for k, v in as_map.items() if k != "source"})
    wrong_type = msgpack.packb({**as_map, "stamp": "yesterday"})
    return {
        "not_msgpack": valid[: len(valid) // 2],
        "not_a_map": msgpack.packb([1, 2, 3]),
        "not_finite": nan_stamp,
        "missing_field": missing,
        "wrong_type": wrong_type,
        "oversized": b"\x00" * (schema_cap + 1),
    }


# (service, its argv, input key, a valid input, the key where its output shows it still works)
CASES: list[tuple[str, list[str], str, Callable[[float], Any], str]] = [
    ("vision", [], "hri/camera/cam0/frame", lambda t: real_frame(1, t), "hri/vision/cam0/objects"),
    ("gesture", [], "hri/camera/cam0/frame", lambda t: real_frame(1, t), "hri/gesture/cam0/hands"),
    (
        "fusion",
        [],
        "hri/speech/kbd/transcript",
        lambda t: make_transcript("stop", mic="kbd", end=t, confidence=1.0, source="test/kbd"),
        "hri/fusion/command",
    ),
]


@pytest.mark.parametrize(
    "service,argv,key,make_valid,output_key",
    [pytest.param(*c, marks=requires_services(c[0])) for c in CASES],
    ids=[c[0] for c in CASES],
)
def test_malformed_inputs_are_counted_and_do_not_stop_the_service(group, service, argv, key, make_valid, output_key):
    group.router()
    proc = group.service(service, *argv)
    client = Client(group.endpoint)
    try:
        client.wait_alive(service, timeout=90)
        client.wait_matched([key])  # the token comes before the subscription: bad samples sent earlier are lost
        out = client.collect(output_key)
        valid = make_valid(time.time())
        bad = bad_payloads(encode(valid), type(valid).MAX_BYTES)
        if isinstance(valid, Frame):
            bad.pop("oversized")  # 64 MiB over loopback only slows the test; test_codec covers the frame cap
        for payload in bad.values():
            client.put_raw(key, payload)
        time.sleep(0.5)
        client.publish(key, make_valid(time.time()))
        out.wait(1, timeout=60)
        stats = client.stats(service)
        assert proc.alive(), group.logs()
        for reason in bad:
            assert stats["rejected"].get(reason, 0) >= 1, (reason, stats)
        assert stats["received"] >= len(bad) + 1
    finally:
        client.close()
