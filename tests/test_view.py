"""`hri view`'s core without zenoh or a browser: the state model, frame budget, overlays, the recording player,
and the PNG snapshot, on the demo photo and the objects the real vision pipeline finds in it."""

from __future__ import annotations

import subprocess
import sys

import cv2
import msgpack
import msgspec
import numpy as np
import pytest

from common.codec import encode
from common.keys import Keys
from common.schema import (
    Clarification,
    Detections,
    Frame,
    FusedCommand,
    GestureEvent,
    Hand,
    ImageEncoding,
    Person,
    Persons,
    Ray,
    Speaker,
    Stats,
    Target,
    Weights,
)
from hri.cli import compact_persons, make_transcript
from hri.recording import NS, SessionWriter
from hri.view.core import ViewState
from hri.view.draw import CANDIDATE, PERSON, SPEAKER, TARGET, render
from hri.view.player import Player
from services.vision.core import VisionPipeline
from services.vision.segment import ColorSegmenter
from testkit.harness import DATA, ROOT

KEYS = Keys("hri")
T0 = 1_790_000_000.0
_TABLE = cv2.imread(str(DATA / "demo" / "table.png"))
assert _TABLE is not None
TABLE: np.ndarray = _TABLE
JPEG = cv2.imencode(".jpg", TABLE)[1].tobytes()
H, W = TABLE.shape[:2]


@pytest.fixture(scope="module")
def objects():
    """What the vision service finds on the demo photo (six candies)."""
    found, quality = VisionPipeline(ColorSegmenter(labels={"*": "candy"})).process("table", TABLE)
    assert len(found) >= 4
    return found, quality


def frame(seq: int, stamp: float, data: bytes = JPEG, encoding: ImageEncoding = "jpeg") -> bytes:
    return encode(
        Frame(stamp=stamp, source="camera/t", seq=seq, cam="table", width=W, height=H, encoding=encoding, data=data)
    )


def detections(objects, stamp: float, seq: int = 1) -> bytes:
    found, quality = objects
    return encode(
        Detections(
            stamp=stamp, source="vision/t", seq=seq, cam="table", width=W, height=H, objects=found, quality=quality
        )
    )


def as_target(obj) -> Target:
    return Target(
        id=obj.id, label=obj.label, color=obj.color, bbox=obj.bbox, center=obj.center, score=obj.score, cam="table"
    )


def command(obj, stamp: float) -> bytes:
    return encode(
        FusedCommand(
            stamp=stamp,
            source="fusion/t",
            id="c1",
            intent="pick_up",
            text="pick up the red one",
            target=as_target(obj),
            confidence=0.9,
            weights=Weights(speech=0.5, vision=0.4, gesture=0.1),
            inputs={"speech": stamp, "vision": stamp, "gesture": None},
            explanation="the only red candy",
            prompt="Command: pick up the red one",
        )
    )


def question(objs, stamp: float) -> bytes:
    return encode(
        Clarification(
            stamp=stamp,
            source="fusion/t",
            id="q1",
            text="bring me the green one",
            reason="ambiguous",
            question="Which one: left or right?",
            candidates=[as_target(o) for o in objs],
        )
    )


def red(objects):
    return next(o for o in objects[0] if o.color == "red")


def test_frames_are_released_latest_only_within_the_budget_and_jpeg_passes_through():
    state = ViewState(KEYS, max_fps=10)
    for i in range(30):  # one second at 30 fps
        state.ingest(KEYS.frame("table"), frame(i, T0 + i / 30), now=i / 30)
    cam = state.cameras["table"]
    assert cam.received == 30 and 9 <= cam.released <= 11
    assert cam.pending is not None and cam.pending.seq == 29  # the newest waits, older ones were replaced
    released = state.tick(now=1.0 + 0.1)
    assert released == ["table"] and state.frame("table").seq == 29
    assert state.frame("table").jpeg == JPEG  # passed through, not re-encoded


def test_png_and_raw_frames_are_encoded_to_jpeg_once_released():
    state = ViewState(KEYS)
    png = cv2.imencode(".png", TABLE)[1].tobytes()
    state.ingest(KEYS.frame("table"), frame(0, T0, png, "png"), now=0.0)
    shown = state.frame("table")
    assert shown.jpeg[:2] == b"\xff\xd8"
    back = cv2.imdecode(np.frombuffer(shown.jpeg, np.uint8), cv2.IMREAD_COLOR)
    assert back.shape == TABLE.shape and np.abs(back.astype(int) - TABLE).mean() < 4
    state.ingest(
        KEYS.frame("cam2"),
        encode(
            Frame(
                stamp=T0, source="camera/t", seq=0, cam="cam2", width=W, height=H, encoding="bgr8", data=TABLE.tobytes()
            )
        ),
        now=0.0,
    )
    assert state.frame("cam2").jpeg[:2] == b"\xff\xd8"


def test_bad_input_on_every_key_is_counted_by_key_and_reason_and_changes_nothing_else(objects):
    state = ViewState(KEYS)
    state.ingest(KEYS.objects("table"), detections(objects, T0), now=0.0)
    before = state.snapshot()
    garbage = {
        KEYS.frame("table"): b"\xc1",
        KEYS.objects("table"): msgpack.packb({"v": 1}),
        KEYS.hands("table"): msgpack.packb([1]),
        KEYS.gesture_event("table"): b"",
        KEYS.transcript("kbd"): msgpack.packb({"v": 1, "stamp": float("inf"), "source": "x"}),
        KEYS.command(): msgpack.packb({"v": 2, "stamp": 1.0, "source": "x"}),
        KEYS.clarification(): b"\x92\x01",
        "hri/unknown/key": msgpack.packb({}),
    }
    for key, payload in garbage.items():
        assert state.ingest(key, payload, now=1.0) is False
    after = state.snapshot()
    assert after["ignored_total"] == len(garbage)
    assert set(after["ignored"]) == set(garbage)
    assert after["ignored"]["hri/unknown/key"] == {"not_in_contract": 1}
    assert after["ignored"][KEYS.frame("table")] == {"not_msgpack": 1}
    assert after["ignored"][KEYS.objects("table")] == {"missing_field": 1}
    assert after["cameras"] == before["cameras"] and after["timeline"] == []


def test_a_flood_of_odd_keys_and_cameras_is_remembered_within_fixed_bounds():
    state = ViewState(KEYS)
    for i in range(1000):
        state.ingest(f"hri/junk/{i}", b"x", now=0)
        state.ingest(
            KEYS.frame(f"cam{i}"),
            encode(
                Frame(
                    stamp=T0,
                    source=f"camera/{i}",
                    seq=0,
                    cam=f"cam{i}",
                    width=2,
                    height=1,
                    encoding="bgr8",
                    data=bytes(6),
                )
            ),
            now=0,
        )
    snap = state.snapshot()
    # 100 (key, reason) pairs, then "(other keys)" once per reason
    assert len(state.ignored) <= 100 + 2 and len(state.cameras) == 32 and len(state.services) <= 256
    assert snap["ignored_total"] == 1000 + 1000 - 32
    assert snap["ignored"]["(other keys)"]["not_in_contract"] > 900


def test_timeline_is_in_source_time_skips_holds_and_partials_and_sends_only_what_is_new(objects):
    state = ViewState(KEYS, timeline_max=5)
    said = make_transcript("pick up the red one", mic="kbd", end=T0 + 2.0, confidence=0.8, source="speech/t")
    partial = make_transcript("pick up", mic="kbd", end=T0 + 1.0, confidence=0.5, source="speech/t")
    partial.final = False
    point = GestureEvent(
        stamp=T0 + 1.5,
        source="gesture/t",
        cam="table",
        width=W,
        height=H,
        gesture="point",
        phase="start",
        start=T0 + 1.4,
        end=T0 + 1.5,
        score=0.9,
        hand="right",
        ray=Ray(origin=[100, 100], direction=[0.6, 0.8]),
    )
    hold = msgspec.structs.replace(point, phase="hold", stamp=T0 + 1.6, end=T0 + 1.6)
    state.ingest(KEYS.command(), command(red(objects), T0 + 2.1), now=0)  # arrives first, happened last
    state.ingest(KEYS.transcript("kbd"), encode(said), now=0)
    state.ingest(KEYS.transcript("kbd"), encode(partial), now=0)
    state.ingest(KEYS.gesture_event("table"), encode(point), now=0)
    state.ingest(KEYS.gesture_event("table"), encode(hold), now=0)
    timeline = state.snapshot()["timeline"]
    assert [e["kind"] for e in timeline] == ["gesture", "transcript", "command"]
    assert timeline[1]["text"] == "pick up the red one" and timeline[1]["confidence"] == 0.8
    assert timeline[2]["weights"] == {"speech": 0.5, "vision": 0.4, "gesture": 0.1}
    assert timeline[2]["prompt"].startswith("Command:") and timeline[2]["explanation"]
    newest = max(e["n"] for e in timeline)
    assert state.snapshot(after_n=newest)["timeline"] == []
    for i in range(5):
        state.ingest(
            KEYS.transcript("kbd"),
            encode(make_transcript(f"stop {i}", mic="kbd", end=T0 + 10 + i, confidence=1.0, source="speech/t")),
            now=0,
        )
    assert len(state.timeline) == 5 and state.timeline[0][2]["text"] == "stop 0"  # bounded, oldest first out


def test_overlay_highlights_the_latest_decision(objects):
    state = ViewState(KEYS)
    state.ingest(KEYS.objects("table"), detections(objects, T0), now=0)
    target = red(objects)
    state.ingest(KEYS.command(), command(target, T0 + 1), now=0)
    layers = state.overlay("table")
    assert layers["target"]["id"] == target.id and layers["target"]["intent"] == "pick_up"
    assert len(layers["objects"]) == len(objects[0]) and layers["quality"]["sharpness"] >= 0
    assert state.overlay("other")["target"] is None  # the target is in another camera
    greens = [o for o in objects[0] if o.color == "green"]
    state.ingest(KEYS.clarification(), question(greens, T0 + 2), now=0)
    layers = state.overlay("table")
    assert layers["target"] is None and {c["id"] for c in layers["candidates"]} == {o.id for o in greens}


def test_services_from_liveliness_stats_and_samples():
    state = ViewState(KEYS)
    state.set_alive("vision", "a", True)
    state.set_stats(
        Stats(
            stamp=T0,
            source="vision/a",
            service="vision",
            instance="a",
            uptime=3.0,
            received=10,
            published=9,
            skipped=1,
            rejected={"not_msgpack": 2},
        )
    )
    state.set_alive("gesture", "b", True)
    state.set_alive("gesture", "b", False)
    rows = {(s["service"], s["instance"]): s for s in state.snapshot()["services"]}
    assert rows[("vision", "a")]["alive"] is True and rows[("vision", "a")]["stats"]["rejected"] == {"not_msgpack": 2}
    assert rows[("gesture", "b")]["alive"] is False


def test_render_draws_the_target_candidates_hand_and_ray(objects):
    target = red(objects)
    hand = Hand(
        hand="right",
        score=0.9,
        landmarks=[[20 + 3 * i, 400 - 4 * i] for i in range(21)],
        gesture="point",
        ray=Ray(origin=[80, 320], direction=[0.8, -0.6]),
    )
    layers = {
        "objects": [o.to_dict() for o in objects[0]],
        "quality": objects[1].to_dict(),
        "hands": [hand.to_dict()],
        "target": {**as_target(target).to_dict(), "intent": "pick_up"},
        "candidates": [as_target(o).to_dict() for o in objects[0] if o.color == "green"],
    }
    out = render(TABLE, layers)
    assert out.shape == TABLE.shape and not np.array_equal(out, TABLE)

    def count(colour, bbox):
        x, y, w, h = (int(v) for v in bbox)
        patch = out[max(y - 3, 0) : y + h + 4, max(x - 3, 0) : x + w + 4].astype(int)
        return int((np.abs(patch - np.array(colour)).sum(axis=2) < 60).sum())

    assert count(TARGET, target.bbox) > 300
    for green in (o for o in objects[0] if o.color == "green"):
        assert count(CANDIDATE, green.bbox) > 300 and count(TARGET, green.bbox) < 50
    assert np.array_equal(TABLE, cv2.imread(str(DATA / "demo" / "table.png")))  # drawn on a copy


def write_session(path, objects) -> None:
    with open(path, "wb") as f:
        writer = SessionWriter(f, KEYS)
        for i in range(40):  # four seconds of a 10 fps camera with detections
            writer.add(KEYS.frame("table"), frame(i, T0 + i / 10), int((T0 + i / 10 + 0.01) * NS))
            writer.add(KEYS.objects("table"), detections(objects, T0 + i / 10, i), int((T0 + i / 10 + 0.03) * NS))
        said = make_transcript("pick up the red one", mic="kbd", end=T0 + 2.0, confidence=0.9, source="speech/t")
        writer.add(KEYS.transcript("kbd"), encode(said), int((T0 + 2.05) * NS))
        writer.add(KEYS.command(), command(red(objects), T0 + 2.0), int((T0 + 2.1) * NS))
        writer.finish()


def test_player_seeks_forward_and_back_and_plays(tmp_path, objects):
    path = tmp_path / "s.mcap"
    write_session(path, objects)
    state = ViewState(KEYS)
    player = Player.open(str(path), state)
    assert player.duration_s == pytest.approx(3.92, abs=0.01)
    player.seek(1.0)
    assert state.frame("table").seq == 10 and not state.timeline  # logged at +1.0 s: just in
    epoch = state.epoch
    player.seek(3.0)
    assert [e[2]["kind"] for e in state.timeline] == ["transcript", "command"]
    assert state.overlay("table")["target"]["color"] == "red"
    player.seek(0.5)  # back: a fresh state
    assert state.epoch == epoch + 1 and not state.timeline and state.frame("table").seq == 5
    player.playing = True
    for _ in range(20):
        player.advance(0.05)
    assert player.offset_s == pytest.approx(1.5, abs=0.01) and state.frame("table").seq >= 13
    player.advance(10.0)
    assert not player.playing and player.offset_s == pytest.approx(player.duration_s)


def test_snapshot_of_a_recording_writes_the_annotated_frame(tmp_path, objects):
    path = tmp_path / "s.mcap"
    write_session(path, objects)
    out = tmp_path / "snap.png"
    res = subprocess.run(
        [sys.executable, "-m", "hri.cli", "view", str(path), "--snapshot", str(out)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert res.returncode == 0, res.stderr
    img = cv2.imread(str(out))
    assert img.shape == TABLE.shape
    x, y, w, h = (int(v) for v in red(objects).bbox)
    box = img[y - 3 : y + h + 4, x - 3 : x + w + 4].astype(int)
    assert (np.abs(box - np.array(TARGET)).sum(axis=2) < 60).sum() > 300
    before = tmp_path / "before.png"  # before the command (1 s into the session): no highlight
    res = subprocess.run(
        [sys.executable, "-m", "hri.cli", "view", str(path), "--snapshot", str(before), "--at", "1.0"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert res.returncode == 0, res.stderr
    box = cv2.imread(str(before))[y - 3 : y + h + 4, x - 3 : x + w + 4].astype(int)
    assert (np.abs(box - np.array(TARGET)).sum(axis=2) < 60).sum() == 0
    res = subprocess.run(
        [sys.executable, "-m", "hri.cli", "view", str(tmp_path / "none.mcap"), "--snapshot", str(out)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert res.returncode == 2 and "cannot open" in res.stderr


def test_http_api_long_polls_serves_the_jpeg_and_controls_the_player(tmp_path, objects, monkeypatch):
    import asyncio

    from aiohttp.test_utils import TestClient, TestServer

    from hri.view import server

    monkeypatch.setattr(server, "LONG_POLL_S", 0.5)
    path = tmp_path / "s.mcap"
    write_session(path, objects)
    state = ViewState(KEYS)
    player = Player.open(str(path), state)
    player.seek(0.0)

    async def go() -> None:
        app = server.make_app(state, {"live": False, "label": "recording"}, player)
        app["changes"] = server.Changes(asyncio.get_running_loop())
        async with TestClient(TestServer(app)) as http:
            first = await (await http.get("/api/state")).json()
            assert first["player"]["duration"] > 3 and first["timeline"] == []
            n = first["cameras"]["table"]["frame"]["n"]
            res = await http.get(f"/api/frame/table?after={n - 1}")
            assert res.status == 200 and await res.read() == JPEG and res.headers["X-Seq"] == "0"
            assert (await http.get(f"/api/frame/table?after={n}")).status == 204  # nothing newer: waits, then 204
            # a seek wakes a waiting state request with the new state
            waiting = asyncio.ensure_future(http.get(f"/api/state?epoch={first['epoch']}&version={first['version']}"))
            await asyncio.sleep(0.1)
            assert not waiting.done()
            assert (await http.post("/api/player", json={"action": "seek", "position": 3.0})).status == 200
            later = await (await waiting).json()
            assert [e["kind"] for e in later["timeline"]] == ["transcript", "command"]
            assert (await http.post("/api/player", json={"action": "jump"})).status == 400
            assert (await http.post("/api/player", data=b"not json")).status == 400
            page = await http.get("/")
            assert page.status == 200 and "view.js" in await page.text()
            assert (await http.get("/static/view.js")).status == 200

    asyncio.run(go())


def test_persons_are_drawn_with_their_ids_and_the_attributed_speaker_is_marked(objects) -> None:
    """Persons (issue #33) are an overlay layer; the person a command was attributed to is marked as speaking for a
    few seconds after it, and the mouth-motion `speaking` of the face stage marks a person too."""
    people = [
        Person(id="person-1", bbox=[20.0, 40.0, 120.0, 300.0], score=1.0, hands=["right"]),
        Person(id="person-2", bbox=[400.0, 40.0, 120.0, 300.0], score=1.0),
    ]

    def persons(stamp: float, speaking: float | None = None) -> bytes:
        shown = [people[0], msgspec.structs.replace(people[1], speaking=speaking)]
        return encode(Persons(stamp=stamp, source="gesture/t", seq=1, cam="table", width=W, height=H, persons=shown))

    state = ViewState(KEYS)
    assert state.ingest(KEYS.persons("table"), persons(T0), now=0)
    layers = state.overlay("table")
    assert [(p["id"], p["speaker"]) for p in layers["persons"]] == [("person-1", False), ("person-2", False)]
    said = msgspec.convert(msgpack.unpackb(command(red(objects), T0 + 1)), FusedCommand)
    said = msgspec.structs.replace(said, speaker=Speaker(person="person-1", confidence=0.8, method="mouth_motion"))
    state.ingest(KEYS.command(), encode(said), now=0)
    state.ingest(KEYS.persons("table"), persons(T0 + 2, speaking=0.9), now=0)
    assert [p["speaker"] for p in state.overlay("table")["persons"]] == [True, True]
    state.ingest(KEYS.persons("table"), persons(T0 + 9, speaking=0.1), now=0)
    assert [p["speaker"] for p in state.overlay("table")["persons"]] == [False, False]  # long after; mouth still
    entry = [e for e in state.snapshot()["timeline"] if e["kind"] == "command"][0]
    assert entry["speaker"]["person"] == "person-1"  # the page shows the attribution on the timeline
    out = render(TABLE, {"persons": [{**people[0].to_dict(), "speaker": True}, {**people[1].to_dict()}]})
    red_edge = out[40:341, 18:23].astype(int)
    assert int((np.abs(red_edge - np.array(SPEAKER)).sum(axis=2) < 60).sum()) > 200
    blue_edge = out[40:341, 398:403].astype(int)
    assert int((np.abs(blue_edge - np.array(PERSON)).sum(axis=2) < 60).sum()) > 100


def test_echo_prints_persons_compactly() -> None:
    line = {
        "key": "hri/gesture/cam0/persons",
        "persons": [
            Person(id="person-1", bbox=[20.4, 40.6, 120.0, 300.2], score=1.0, hands=["right"]).to_dict(),
            Person(id="person-2", bbox=[400.0, 40.0, 120.0, 300.0], score=0.9).to_dict(),
        ],
    }
    assert compact_persons(line)["persons"] == [
        {"id": "person-1", "bbox": [20, 41, 120, 300], "score": 1.0, "hands": ["right"]},
        {"id": "person-2", "bbox": [400, 40, 120, 300], "score": 0.9},
    ]
    assert compact_persons({"key": "k", "hands": []}) == {"key": "k", "hands": []}
