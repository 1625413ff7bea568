"""`hri view` with depth: positions in the object and target labels (common/view/draw.py; view.js mirrors it)."""

from __future__ import annotations

import numpy as np

from common.view.draw import BOX, object_position, render


def test_positions_are_written_in_metres_only_when_known():
    assert object_position({"label": "cup"}) == ""
    assert object_position({"label": "cup", "position": None}) == ""
    assert object_position({"label": "cup", "position": [0.0412, -0.1, 0.963]}) == " (+0.04, -0.10, 0.96) m"


def test_a_positioned_object_gets_the_longer_label():
    img = np.full((200, 400, 3), 255, np.uint8)
    obj = {"id": "cam0-o1", "label": "cup", "color": "red", "score": 0.9, "bbox": [20, 60, 80, 80],
           "center": [60, 100]}

    def label_width(layers) -> int:
        out = render(img, layers)
        band = out[30:60]  # the label sits just above the box
        cols = np.flatnonzero((np.abs(band.astype(int) - np.array(BOX)).sum(axis=2) < 60).any(axis=0))
        return int(cols.max() - cols.min()) if cols.size else 0

    plain = label_width({"objects": [obj]})
    placed = label_width({"objects": [{**obj, "position": [0.04, 0.01, 0.96]}]})
    assert placed > plain + 60  # " (+0.04, +0.01, 0.96) m" is there
