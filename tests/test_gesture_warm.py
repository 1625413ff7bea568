"""Warm start (issue #41) without Zenoh: graphs warmed on a blank frame answer a camera's frames exactly as graphs
built on its first frame do, and `GraphSupply` hands out, builds and closes sets of graphs as the shell needs."""

from __future__ import annotations

import threading

import pytest

from services.gesture.core import GestureCore, GestureSettings, build_graphs
from services.gesture.warm import GraphSupply
from testkit.frames import bgr_frame
from testkit.harness import DATA
from testkit.images import read_image

PHOTOS = [DATA / "demo" / "stop.png", DATA / "demo" / "pointing.png", DATA / "images" / "hands" / "handSrc.jpg"]


def run(core: GestureCore, cam: str, frames: int = 6) -> list[tuple]:
    """Each photo shown `frames` times on `cam`, 10 fps: the wire samples and events of every frame."""
    out = []
    k = 0
    for path in PHOTOS:
        img = read_image(str(path))
        for _ in range(frames):
            result = core.process(bgr_frame(img, k, 100.0 + k / 10, cam=cam), img, fresh=k == 0)
            events = [(e.gesture, e.phase, e.hand) for e in result.events]
            out.append((result.hands.hands, result.bodies, result.persons, result.faces, events))
            k += 1
    return out


def test_warmed_graphs_answer_a_cameras_frames_as_graphs_built_on_its_first_frame() -> None:
    settings = GestureSettings()
    cold, warm = GestureCore(settings, "gesture/test", 2), GestureCore(settings, "gesture/test", 2)
    try:
        warm.adopt("cam0", build_graphs(settings))  # run once on a blank frame, before any frame of the camera
        assert set(warm.cameras) == {"cam0"} and "cam0" in warm.faces.stages and "cam0" in warm.people.stages
        from_cold, from_warm = run(cold, "cam0"), run(warm, "cam0")
        assert any(hands for hands, *_ in from_warm) and any(events for *_, events in from_warm)
        assert from_warm == from_cold
        faces = [f for *_, f, _ in from_warm if f is not None]
        assert faces and all(face.id.startswith("cam0/face-") for f in faces for face in f.faces)
    finally:
        cold.close()
        warm.close()


class Graphs:
    """A stand-in set of graphs: counts closes."""

    def __init__(self, n: int) -> None:
        self.n = n
        self.closed = False

    def close(self) -> None:
        self.closed = True


def build_one(made: list[Graphs], gate: threading.Event) -> Graphs:
    """The first set is built at start (prepare); the others, on the builder thread, once `gate` is set."""
    if made:
        gate.wait(10)
    made.append(Graphs(len(made)))
    return made[-1]


def test_named_cameras_get_their_own_set_and_a_new_one_waits_for_a_background_build() -> None:
    made: list[Graphs] = []
    gate = threading.Event()  # background builds wait for it: the test decides when they finish
    built: list[float] = []
    supply = GraphSupply(lambda: build_one(made, gate), spares=0, on_built=built.append)
    supply.prepare(["front"], 0)
    assert supply.built == 1
    assert supply.take("front") is made[0]  # its own, built before the service was live
    assert supply.take("side") is None  # not named: its set is built in the background
    assert supply.take("side") is None  # asked again before it is done: still one build
    gate.set()
    for _ in range(100):
        if supply.ready:
            break
        threading.Event().wait(0.05)
    side = supply.take("side")
    assert side is made[1] and supply.built == 2 and len(built) == 1
    threading.Event().wait(0.2)
    assert len(made) == 2  # nothing more wanted: no set built ahead with spares=0
    supply.close()


@pytest.mark.parametrize("spares", [1, 2])
def test_spares_are_kept_built_ahead_and_closed_with_the_supply(spares: int) -> None:
    made: list[Graphs] = []
    gate = threading.Event()
    gate.set()
    changes: list[tuple[int, int]] = []  # what the stats gauges are told
    supply = GraphSupply(lambda: build_one(made, gate), spares=spares, on_change=lambda *c: changes.append(c))
    supply.prepare([], spares)  # with a wildcard: sets for the cameras to come
    assert changes == [(spares, spares)]
    first = supply.take("a")
    assert first is made[0]
    for _ in range(100):  # the one taken is built again
        if supply.ready == spares:
            break
        threading.Event().wait(0.05)
    assert supply.ready == spares and supply.built == spares + 1
    assert changes[1] == (spares, spares - 1) and changes[-1] == (spares + 1, spares)  # taken, then built again
    supply.close()
    assert not first.closed  # the camera's: closed with the core
    assert all(g.closed for g in made[1:])
