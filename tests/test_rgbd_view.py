"""`hri view` with depth: positions in the object and target labels (hri/view/draw.py; view.js mirrors it)."""

from __future__ import annotations

import numpy as np

from hri.view.draw import BOX, object_position, render


def test_positions_are_written_in_metres_only_when_known():
    assert object_position({"label": "cup"}) == ""
    assert object_position({"label": "cup", "position": None}) == ""
    assert object_position({"label": "cup", "position": [0.0412, -0.1, 0.963]}) == " (+0.04, -0.10, 0.96) m"


def test_a_positioned_object_gets_the_longer_label():
    img = np.full((200, 400, 3), 255, np.uint8)
    obj = {"id": "cam0-o1", "label": "cup", "color": "red", "score": 0.9, "bbox": [20, 60, 80, 80], "center": [60, 100]}

    def label_width(layers) -> int:
        out = render(img, layers)
        band = out[30:60]  # the label sits just above the box
        cols = np.flatnonzero((np.abs(band.astype(int) - np.array(BOX)).sum(axis=2) < 60).any(axis=0))
        return int(cols.max() - cols.min()) if cols.size else 0

    plain = label_width({"objects": [obj]})
    placed = label_width({"objects": [{**obj, "position": [0.04, 0.01, 0.96]}]})
    assert placed > plain + 60  # " (+0.04, +0.01, 0.96) m" is there


def depth_sample(seq: int = 0, cam: str = "table"):
    from common.depth import depth_frame
    from common.schema import CameraInfo

    depth = np.full((120, 160), 2000, np.uint16)  # a wall at 2 m
    depth[30:70, 40:90] = 800  # an object at 0.8 m
    depth[100:, :] = 0  # no measurement
    info = CameraInfo(width=160, height=120, k=[130.0, 0, 79.5, 0, 130.0, 59.5, 0, 0, 1], frame_id="cam_optical")
    return depth_frame(
        depth,
        stamp=1_700_000_000.0 + seq,
        source="camera/t",
        seq=seq,
        cam=cam,
        depth_scale=0.001,
        camera_info=info,
        compression="png",
    )


def test_the_depth_overlay_colours_near_red_far_blue_and_holes_black():
    import cv2

    from common.codec import encode
    from common.keys import Keys
    from hri.view.core import ViewState

    keys = Keys("hri")
    state = ViewState(keys)
    assert state.depth_picture("table") is None
    assert state.ingest(keys.depth("table"), encode(depth_sample(3)), now=0.0)
    assert state.snapshot()["cameras"]["table"]["depth"]["seq"] == 3
    seq, _, jpeg = state.depth_picture("table")
    assert seq == 3 and state.depth_picture("table")[2] is jpeg  # colourized once per depth frame
    img = cv2.imdecode(np.frombuffer(jpeg, np.uint8), cv2.IMREAD_COLOR).astype(int)
    assert img.shape == (120, 160, 3)
    b, g, r = img[50, 60]
    assert r > 2 * b  # near: red
    b, g, r = img[10, 10]
    assert b > 2 * r  # far: blue
    assert img[110, 80].sum() < 40  # no measurement: black


def test_the_depth_endpoint_serves_the_picture_and_204_without_depth(monkeypatch):
    import asyncio

    from aiohttp.test_utils import TestClient, TestServer

    from common.codec import encode
    from common.keys import Keys
    from hri.view import server
    from hri.view.core import ViewState

    keys = Keys("hri")
    state = ViewState(keys)
    state.ingest(keys.depth("table"), encode(depth_sample(5)), now=0.0)

    async def go() -> None:
        app = server.make_app(state, {"live": True, "label": "test"}, None)
        app["changes"] = server.Changes(asyncio.get_running_loop())
        async with TestClient(TestServer(app)) as http:
            res = await http.get("/api/depth/table")
            assert res.status == 200 and res.headers["X-Seq"] == "5"
            assert (await res.read())[:2] == b"\xff\xd8"
            assert (await http.get("/api/depth/other")).status == 204

    asyncio.run(go())
