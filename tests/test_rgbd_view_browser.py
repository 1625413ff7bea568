"""`hri view` with an RGB-D camera in a real browser: positions in the labels' data and the depth overlay
toggle (the real stack: camera on the YCB-Video RGB-D frames, vision, view; headless Chromium)."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from testkit.browser import Browser, require_chromium, start_view
from testkit.harness import ProcessGroup
from testkit.shared import shared_path

pytestmark = pytest.mark.integration


def panel_shot(tab) -> np.ndarray:
    rect = tab.js("JSON.parse(JSON.stringify(document.querySelector('#cam-cam0 canvas').getBoundingClientRect()))")
    png = tab.screenshot({"x": rect["x"], "y": rect["y"], "width": rect["width"], "height": rect["height"]})
    shot = cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_COLOR)
    assert shot is not None, "the screenshot is not a PNG"
    return shot.astype(int)


def redraw(tab) -> None:
    """Have the page fetch the latest frame at once and wait until it has drawn it (not a fixed sleep: under load
    a second was not always enough)."""
    drawn = tab.js("hriView.framesDrawn")
    tab.js("hriView.cams.cam0.n = -1")  # the next fetch returns the latest frame, not the one after it
    tab.wait_for(f"hriView.framesDrawn > {drawn}", 30, "a frame drawn after the change")


def test_depth_toggle_overlays_the_depth_and_objects_carry_positions(tmp_path):
    require_chromium()
    src = shared_path("data/rgbd/ycb_video")
    folder = tmp_path / "ycb"
    folder.mkdir()
    (folder / "000002-color.png").write_bytes((src / "000002-color.png").read_bytes())
    (folder / "000002-depth.png").write_bytes((src / "000002-depth.png").read_bytes())
    (folder / "intrinsics.json").write_text(
        json.dumps(
            {
                "width": 640,
                "height": 480,
                "fx": 1066.778,
                "fy": 1067.487,
                "cx": 312.9869,
                "cy": 241.3109,
                "depth_scale": 0.0001,
            }
        )
    )
    group = ProcessGroup()
    browser = None
    try:
        group.router()
        group.service("vision")
        group.service("camera", "--source", str(folder), "--fps", "5", "--loop")
        _, url = start_view(group)
        browser = Browser()
        tab = browser.tab(url)
        tab.wait_for("window.hriView && hriView.framesDrawn > 2", 60, "camera frames")
        tab.wait_for("!document.querySelector('label.depth-toggle').hidden", 30, "the depth toggle")
        tab.wait_for("(hriView.state.cameras.cam0.objects || []).some((o) => o.position)", 30, "objects with positions")
        before = panel_shot(tab)
        tab.js("document.querySelector('[data-depth=cam0]').click()")
        tab.wait_for("hriView.cams.cam0.depthBitmap !== null", 30, "the depth picture")
        redraw(tab)
        after = panel_shot(tab)
        cv2.imwrite(str(tmp_path / "depth-overlay.png"), after.astype(np.uint8))
        assert np.abs(after - before).mean() > 15, "the depth overlay changed nothing"
        # jet: the table and objects at ~1 m lean red/orange, the far background blue; holes stay dark
        tab.js("document.querySelector('[data-depth=cam0]').click()")
        redraw(tab)
        again = panel_shot(tab)
        assert np.abs(again - before).mean() < np.abs(after - before).mean() / 2, "toggling off kept the overlay"
    finally:
        if browser is not None:
            browser.close()
        group.close()
