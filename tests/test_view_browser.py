"""`hri view` in a real browser: the real stack on the demo photo, the page in headless Chromium.

What a person would see is asserted: the words and the command in the timeline, the target highlighted
inside its box in a screenshot of the camera panel, bad input counted without breaking the page, and a
recording of the same session played back with its slider.
"""

from __future__ import annotations

import re
import socket
import time
from pathlib import Path
from typing import Any

import cv2
import msgpack
import numpy as np
import pytest

from common.schema import Person, Persons
from testkit.browser import Browser, require_chromium, start_view
from testkit.harness import DATA, Client, ProcessGroup, requires_services
from testkit.images import read_image

pytestmark = [pytest.mark.integration, requires_services("camera", "vision", "fusion")]

TABLE = DATA / "demo" / "table.png"
TARGET_RGB = (255, 0, 255)  # magenta, hri/view/draw.py TARGET


def rss_kib(pid: int) -> int:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1])
    raise RuntimeError("no VmRSS")


@pytest.fixture(scope="module")
def live(tmp_path_factory):
    require_chromium()
    group = ProcessGroup()
    browser = None
    client = None
    try:
        group.router()
        group.service("camera", "--source", str(TABLE), "--cam", "table", "--fps", "10", "--loop")
        # --max-rate at the camera's rate: nothing skipped, the rate shown in the services table (issue #42)
        group.service("vision", "--labels", str(DATA / "demo" / "labels.json"), "--max-rate", "10")
        group.service("fusion")
        recording = tmp_path_factory.mktemp("view") / "session.mcap"
        recorder = group.start("record", "hri.cli", "record", "-o", str(recording), "hri/**")
        client = Client(group.endpoint)
        for name in ("camera", "vision", "fusion"):
            client.wait_alive(name, timeout=90)
        view, url = start_view(group)
        browser = Browser()
        yield {
            "group": group,
            "client": client,
            "browser": browser,
            "view": view,
            "url": url,
            "recorder": recorder,
            "recording": recording,
        }
    finally:
        if browser is not None:
            browser.close()
        if client is not None:
            client.close()
        group.close()


def target_pixels(png: bytes, rect: dict, frame_w: int, bbox: list[float]) -> tuple[int, float]:
    """(highlight-coloured pixels inside the target's box, grey-level spread of the whole panel)."""
    shot = cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_COLOR)
    assert shot is not None, "the screenshot is not a PNG"
    scale = shot.shape[1] / frame_w
    x, y, w, h = (int(round(v * scale)) for v in bbox)
    box = shot[max(y - 2, 0) : y + h + 3, max(x - 2, 0) : x + w + 3].astype(int)
    b, g, r = box[..., 0], box[..., 1], box[..., 2]
    magenta = (r > 200) & (b > 200) & (g < 90)
    return int(magenta.sum()), float(cv2.cvtColor(shot, cv2.COLOR_BGR2GRAY).std())


def test_page_shows_the_transcript_the_command_and_highlights_the_target(live):
    tab = live["browser"].tab(live["url"])
    tab.wait_for("window.hriView && hriView.connected && hriView.framesDrawn > 2", 60, "camera frames")
    assert tab.js("document.querySelector('#cam-table canvas') !== null")
    res = live["group"].hri("say", "pick up the red one")
    assert res.returncode == 0, res.stderr

    tab.wait_for(
        "document.querySelector('#timeline').innerText.includes('pick up the red one')",
        30,
        "the transcript in the timeline",
    )
    summary = tab.wait_for(
        "(document.querySelector('#timeline li.command summary') || {}).innerText", 30, "a command in the timeline"
    )
    assert "pick_up" in summary and "red candy" in summary, summary
    # the command expands to its explanation, the modality weights as bars and the planner prompt
    tab.js("document.querySelector('#timeline li.command details').open = true")
    assert tab.js("document.querySelectorAll('#timeline li.command .weights .bar').length") == 3
    assert tab.js("document.querySelector('#timeline li.command .explanation').innerText.length") > 10
    assert "red" in tab.js("document.querySelector('#timeline li.command pre.prompt').innerText")
    # fusion's estimate of each source's clock offset (docs/foundation.md) in the services table
    clocks = tab.wait_for(
        "(document.querySelector('#services tr[data-service=fusion] td.clocks') || {}).innerText",
        30,
        "fusion's clock offsets",
    )
    assert "vision/" in clocks and " ms" in clocks, clocks
    rates = tab.wait_for(
        "(document.querySelector('#services tr[data-service=vision] td.rates') || {}).innerText", 30, "vision's rate"
    )
    assert rates == "model ≤ 10.0 Hz", rates

    target = tab.wait_for("hriView.state.cameras.table.target", 10, "the target in the overlay")
    assert target["color"] == "red"
    time.sleep(0.5)  # a frame drawn after the decision
    rect = tab.js("JSON.parse(JSON.stringify(document.querySelector('#cam-table canvas').getBoundingClientRect()))")
    frame_w = tab.js("document.querySelector('#cam-table canvas').width")
    png = tab.screenshot({"x": rect["x"], "y": rect["y"], "width": rect["width"], "height": rect["height"]})
    Path(live["recording"]).with_name("camera-panel.png").write_bytes(png)
    inside, spread = target_pixels(png, rect, frame_w, target["bbox"])
    assert spread > 20, "the camera panel is blank"
    assert inside > 200, f"only {inside} highlight pixels inside the target's box"
    # and the highlight is only there: another object's box has none
    others = [o for o in tab.js("hriView.state.cameras.table.objects") if o["id"] != target["id"]]
    assert others and target_pixels(png, rect, frame_w, others[0]["bbox"])[0] < inside / 10
    tab.close()
    live["browser"].tabs.remove(tab)


def test_bad_input_on_any_key_is_ignored_counted_and_the_page_goes_on(live):
    tab = live["browser"].tab(live["url"])
    tab.wait_for("window.hriView && hriView.connected && hriView.framesDrawn > 0", 60, "camera frames")
    client = live["client"]
    bad = {
        "hri/camera/table/frame": b"\xc1 not msgpack",
        "hri/vision/table/objects": msgpack.packb({"v": 1, "stamp": 1.0}),
        "hri/gesture/table/hands": msgpack.packb([1, 2, 3]),
        "hri/gesture/table/event": msgpack.packb({"v": 1, "stamp": float("nan"), "source": "x"}),
        "hri/speech/kbd/transcript": msgpack.packb({"v": 1, "stamp": 5.0, "source": "x", "text": 7}),
        "hri/fusion/command": b"",
        "hri/fusion/clarification": msgpack.packb({"v": 2, "stamp": 5.0, "source": "x"}),
    }
    for key, payload in bad.items():
        client.put_raw(key, payload)
    shown = tab.wait_for(
        f"hriView.state && hriView.state.ignored_total >= {len(bad)} && document.querySelector('#ignored').innerText",
        20,
        "the ignored count",
    )
    assert re.search(r"ignored: \d+", shown)
    listed = tab.js("document.querySelector('#ignored-list').innerText")
    for key in bad:
        assert key in listed, listed
    drawn = tab.js("hriView.framesDrawn")
    tab.wait_for(f"hriView.framesDrawn > {drawn + 5}", 20, "frames still drawn after bad input")
    assert tab.js("hriView.pageErrors") == 0
    assert live["view"].alive()
    tab.close()
    live["browser"].tabs.remove(tab)


def test_persons_are_drawn_and_the_speaker_is_marked_on_the_page(live: dict[str, Any]) -> None:
    """Persons (issue #33) published for the camera: the page draws each person's box with their id, the one whose
    mouth moves (`speaking`) in the speaker's red, the other in the person blue."""
    tab = live["browser"].tab(live["url"])
    tab.wait_for("window.hriView && hriView.connected && hriView.framesDrawn > 0", 60, "camera frames")
    frame_w = tab.js("document.querySelector('#cam-table canvas').width")
    frame_h = tab.js("document.querySelector('#cam-table canvas').height")
    speaker = Person(id="person-1", bbox=[10.0, 10.0, frame_w / 3, frame_h - 20.0], score=1.0, speaking=0.9)
    other = Person(id="person-2", bbox=[frame_w * 0.6, 10.0, frame_w / 3, frame_h - 20.0], score=1.0, speaking=0.0)
    for seq in range(3):
        sample = Persons(
            stamp=time.time(),
            source="gesture/t",
            seq=seq,
            cam="table",
            width=frame_w,
            height=frame_h,
            persons=[speaker, other],
        )
        live["client"].publish("hri/gesture/table/persons", sample)
        time.sleep(0.1)
    shown = tab.wait_for(
        "hriView.state.cameras.table.persons.length === 2 && hriView.state.cameras.table.persons",
        20,
        "the persons in the overlay",
    )
    assert [(p["id"], p["speaker"]) for p in shown] == [("person-1", True), ("person-2", False)]
    drawn = tab.js("hriView.framesDrawn")
    tab.wait_for(f"hriView.framesDrawn > {drawn + 2}", 20, "frames drawn with the persons")
    rect = tab.js("JSON.parse(JSON.stringify(document.querySelector('#cam-table canvas').getBoundingClientRect()))")
    png = tab.screenshot({"x": rect["x"], "y": rect["y"], "width": rect["width"], "height": rect["height"]})
    picture = cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_COLOR)
    assert picture is not None
    shot = picture.astype(int)
    scale = shot.shape[1] / frame_w

    def edge(person: Person, rgb: tuple[int, int, int]) -> int:
        x = int(round(person.bbox[0] * scale))
        strip = shot[:, max(x - 3, 0) : x + 4]
        return int((np.abs(strip - np.array(rgb[::-1])).sum(axis=2) < 60).sum())

    assert edge(speaker, (255, 60, 60)) > 100 and edge(other, (60, 160, 255)) > 50
    assert tab.js("hriView.pageErrors") == 0
    tab.close()
    live["browser"].tabs.remove(tab)


def test_many_tabs_and_a_tab_that_never_reads_do_not_grow_the_server(live):
    url, pid = live["url"], live["view"].pid
    host, port = re.match(r"http://([^:/]+):(\d+)/", url).groups()
    import asyncio

    import aiohttp

    async def tab(stop: asyncio.Event) -> int:
        """A tab as the page behaves: long-poll state and frames in a loop."""
        n, frames = -1, 0
        async with aiohttp.ClientSession() as http:
            while not stop.is_set():
                async with http.get(f"{url}api/frame/table?after={n}") as res:
                    if res.status == 200:
                        n = int(res.headers["X-Frame-N"])
                        await res.read()
                        frames += 1
                async with http.get(f"{url}api/state?epoch=0") as res:
                    await res.read()
        return frames

    def stalled() -> socket.socket:
        """A tab that asks for frames again and again and never reads a byte of the answers."""
        s = socket.create_connection((host, int(port)))
        s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
        s.sendall(b"".join(f"GET /api/frame/table?after={i} HTTP/1.1\r\nHost: x\r\n\r\n".encode() for i in range(200)))
        return s

    async def run(seconds: float) -> list[int]:
        stop = asyncio.Event()
        tasks = [asyncio.create_task(tab(stop)) for _ in range(20)]
        await asyncio.sleep(seconds)
        stop.set()
        return await asyncio.gather(*tasks)

    loop = asyncio.new_event_loop()
    browser = live["browser"]
    pages = []
    try:
        loop.run_until_complete(run(3.0))  # warm up: buffers, caches, first allocations
        before = rss_kib(pid)
        pages = [browser.tab(url) for _ in range(3)]  # real pages too, beside the 20 scripted ones
        sockets = [stalled() for _ in range(5)]
        frames = loop.run_until_complete(run(15.0))
        after = rss_kib(pid)
        for page in pages:
            assert page.js("hriView.framesDrawn") > 30
        for s in sockets:
            s.close()
    finally:
        loop.close()
        for page in pages:
            page.close()
            browser.tabs.remove(page)
    assert min(frames) > 30, f"some tabs got too few frames: {frames}"  # ~10 fps each, despite the stalled ones
    print(f"hri view RSS: {before} KiB before the tabs, {after} KiB after 15 s of them; frames per tab {frames}")
    assert after - before < 20_000, f"server RSS grew {before} -> {after} KiB"
    assert live["view"].alive()


def test_snapshot_of_the_live_bus_writes_the_annotated_camera_frame(live, tmp_path):
    out = tmp_path / "live.png"
    res = live["group"].hri(
        "view", "--snapshot", str(out), "--cam", "table", "--wait", "1", "--timeout", "30", timeout=60
    )
    assert res.returncode == 0, res.stderr
    img = read_image(str(out))
    table = read_image(str(TABLE))
    assert img.shape == table.shape and img.std() > 20

    def box_green(image):  # draw.py BOX; the photo's green candies come close, so count only what was drawn
        return np.abs(image.astype(int) - np.array((80, 220, 0))).sum(axis=2) < 40

    drawn = box_green(img) & ~box_green(table)
    assert drawn.sum() > 2000, f"no detection boxes drawn ({drawn.sum()} box-coloured pixels added)"
    res = live["group"].hri("view", "--snapshot", str(out), "--at", "5")
    assert res.returncode == 2 and "--at needs" in res.stderr


def test_recording_opens_with_a_slider_and_shows_the_same_command(live):
    time.sleep(1.0)
    code, _ = live["recorder"].terminate(timeout=15)
    assert code == 0, live["recorder"].output()
    view, url = start_view(live["group"], str(live["recording"]), name="view-recording")
    tab = live["browser"].tab(url)
    player = tab.wait_for("hriView.state && hriView.state.player", 30, "the player")
    assert player["duration"] > 3 and not player["playing"]
    assert tab.js("document.querySelector('#player').hidden") is False
    assert "recording" in tab.js("document.querySelector('#mode').innerText")
    # a person drags the slider to the end
    tab.js(
        f"(() => {{ const s = document.querySelector('#slider'); s.value = {player['duration']};"
        "s.dispatchEvent(new Event('input')); s.dispatchEvent(new Event('change')); })()"
    )
    summary = tab.wait_for(
        "(document.querySelector('#timeline li.command summary') || {}).innerText", 30, "the recorded command"
    )
    assert "pick_up" in summary and "red candy" in summary
    assert "pick up the red one" in tab.js("document.querySelector('#timeline').innerText")
    tab.wait_for("hriView.framesDrawn > 0", 20, "a recorded frame")
    # back to the start, then play: the slider moves on its own
    tab.js(
        "(() => { const s = document.querySelector('#slider'); s.value = 0;"
        "s.dispatchEvent(new Event('input')); s.dispatchEvent(new Event('change')); })()"
    )
    tab.wait_for(
        "hriView.state.player.position < 0.5 && !document.querySelector('#timeline li.command')",
        20,
        "the session rewound",
    )
    tab.js("document.querySelector('#play').click()")
    tab.wait_for("Number(document.querySelector('#slider').value) > 1.0", 20, "the slider moving")
    assert tab.js("hriView.state.player.playing") is True
    view.terminate()
