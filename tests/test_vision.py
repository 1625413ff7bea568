"""Vision on real photos: colours, counts, the red hue wrap, white/black objects, quality, ids, the ONNX path."""

from collections import Counter

import cv2
import numpy as np
import pytest

from common.schema import ImageQuality
from services.fusion.evidence import image_quality as fusion_trust
from services.vision.color import HUE_RANGES, color_name
from services.vision.core import VisionPipeline
from services.vision.quality import image_quality
from services.vision.segment import ColorSegmenter
from services.vision.track import Tracker
from services.vision.yolo import Letterbox, ModelError, YoloDetector, decode, letterbox
from testkit.harness import DATA
from testkit.vision import tiny_yolo

TABLETOP = DATA / "images" / "tabletop"


def photo(name: str) -> np.ndarray:
    path = DATA / "demo" / name if (DATA / "demo" / name).exists() else TABLETOP / name
    img = cv2.imread(str(path))
    assert img is not None, path
    return img


def colours(img: np.ndarray) -> Counter:
    return Counter(d.color for d in ColorSegmenter().detect(img))


# Counted once by looking at the photos (smarties.png: 4 red, 2 orange, 3 green incl. one cut by the left
# border, 3 blue, 2 dark brown — one cut by the bottom border).
def test_smarties_counts_and_colours_match_the_photo():
    found = colours(photo("smarties.png"))
    assert {c: found[c] for c in ("red", "orange", "green", "blue")} == {"red": 4, "orange": 2, "green": 3, "blue": 3}
    assert found["black"] >= 1  # dark brown has no hue of its own: it reads black
    assert found["yellow"] == found["purple"] == found["white"] == 0


def test_each_smarties_box_holds_one_candy_of_its_colour():
    img = photo("smarties.png")
    hsv = cv2.cvtColor(img, cv2.COLOR_BGR2HSV)
    for det in ColorSegmenter().detect(img):
        x, y, w, h = (int(v) for v in det.bbox)
        assert 0.5 < w / h < 2.0 or det.color == "black", det  # round candies (or a cut-off one)
        assert det.color == color_name(hsv[y + h // 3 : y + 2 * h // 3, x + w // 3 : x + 2 * w // 3])[0]


def test_demo_scenes_have_the_objects_the_demo_relies_on():
    table = colours(photo("table.png"))
    assert (table["red"], table["green"], table["blue"], table["orange"]) == (1, 2, 2, 1)
    pointing = colours(photo("pointing.png"))
    assert (pointing["red"], pointing["blue"]) == (1, 1)
    red = [d for d in ColorSegmenter().detect(photo("pointing.png")) if d.color == "red"][0]
    assert abs(red.center[0] - 555) < 30 and abs(red.center[1] - 125) < 30
    blue = [d for d in ColorSegmenter().detect(photo("pointing.png")) if d.color == "blue"][0]
    assert abs(blue.center[0] - 540) < 30 and abs(blue.center[1] - 320) < 30  # the hand is neither


def touching_candies() -> np.ndarray:
    """Real red, blue and orange candies cut from smarties.png and laid side by side so that they touch."""
    img = photo("smarties.png")
    canvas = np.full((160, 260, 3), 255, np.uint8)
    x = 20
    for x0, y0 in ((260, 186), (319, 210), (177, 183)):  # red, blue, orange: 58×57 patches, white margins
        patch = img[y0 : y0 + 57, x0 : x0 + 58]
        canvas[50:107, x : x + 58] = np.minimum(canvas[50:107, x : x + 58], patch)  # darker pixel wins: no seams
        x += 50
    return canvas


def test_touching_candies_of_different_colours_stay_separate_objects():
    img = touching_candies()
    hsv = cv2.cvtColor(cv2.GaussianBlur(img, (5, 5), 0), cv2.COLOR_BGR2HSV)
    vivid = cv2.inRange(hsv, (0, 100, 75), (180, 255, 255))
    n, _ = cv2.connectedComponents(vivid)
    assert n - 1 == 1, "the three candies must touch for this test to mean anything"
    found = sorted(ColorSegmenter().detect(img), key=lambda d: d.bbox[0])
    assert [d.color for d in found] == ["red", "blue", "orange"]
    for d, left in zip(found, (20, 70, 120)):
        assert abs(d.center[0] - (left + 29)) < 8 and 40 < d.bbox[2] < 62, d


def test_red_uses_both_ends_of_the_hue_circle():
    img = photo("smarties.png")
    hsv = cv2.cvtColor(cv2.GaussianBlur(img, (5, 5), 0), cv2.COLOR_BGR2HSV)
    reds = [d for d in ColorSegmenter().detect(img) if d.color == "red"]
    wrapped = 0
    for det in reds:
        x, y, w, h = (int(v) for v in det.bbox)
        pix = hsv[y : y + h, x : x + w].reshape(-1, 3)
        pix = pix[(pix[:, 1] >= 100) & (pix[:, 2] >= 75)]
        high = (pix[:, 0] >= 170).mean()
        low = (pix[:, 0] < 5).mean()
        assert low > 0.2, det
        wrapped += high > 0.15
        # with the low range alone these pixels would be lost, and the share of red would fall
        only_low = np.bincount(pix[:, 0], minlength=180)[:5].sum() / len(pix)
        assert color_name(pix)[0] == "red" and only_low < color_name(pix)[1]
    assert wrapped >= 2, "real red candies have hue on both sides of 0"
    assert HUE_RANGES["red"][1] == (170, 180)


def test_white_and_black_objects_on_a_grey_table():
    found = ColorSegmenter().detect(photo("stuff.jpg"))
    by_colour = Counter(d.color for d in found)
    assert by_colour["white"] >= 2  # the ball and the coin
    assert by_colour["black"] >= 1  # the pencil
    coin = [d for d in found if d.color == "white" and d.bbox[2] < 60]
    assert coin and abs(coin[0].center[0] - 210) < 15 and abs(coin[0].center[1] - 307) < 15
    pencil = max((d for d in found if d.color == "black"), key=lambda d: d.bbox[2])
    assert pencil.bbox[2] > 150  # the long diagonal pencil, not a speck
    assert not any(d.bbox[2] * d.bbox[3] > 0.25 * 640 * 480 for d in found)  # the table is not an object


@pytest.mark.parametrize("name", ["smarties.png", "stuff.jpg", "fruits.jpg", "table.png", "pointing.png"])
def test_quality_drops_for_dark_and_blurred_copies(name):
    img = photo(name)
    b, c, s = image_quality(img)
    dark = image_quality((img * 0.15).astype(np.uint8))
    blurred = image_quality(cv2.GaussianBlur(img, (21, 21), 0))
    assert dark[0] < 0.2 and dark[0] < b / 4 and dark[1] < c / 3
    assert blurred[2] < 0.1 and blurred[2] < s / 3
    trust = lambda q: fusion_trust(ImageQuality(brightness=q[0], contrast=q[1], sharpness=q[2]))  # noqa: E731
    assert trust((b, c, s)) > 0.9
    assert trust(dark) < 0.3 and trust(blurred) < 0.6


def test_ids_stay_stable_while_the_scene_moves_and_are_not_reused():
    img = photo("table.png")
    pipeline = VisionPipeline(ColorSegmenter())
    first, _ = pipeline.process("cam0", img)
    assert len({o.id for o in first}) == len(first) >= 6
    previous = first
    for step in range(1, 13):  # the scene slides 3 px right and 2 px down per frame
        m = np.float32([[1, 0, 3 * step], [0, 1, 2 * step]])
        moved = cv2.warpAffine(img, m, (img.shape[1], img.shape[0]), borderValue=(255, 255, 255))
        objects, _ = pipeline.process("cam0", moved)
        for o in objects:
            if o.color == "black":
                continue  # the cut-off candy in the corner changes shape as it moves
            same = [p for p in previous if p.color == o.color]
            before = min(
                same, key=lambda p: (p.center[0] + 3 - o.center[0]) ** 2 + (p.center[1] + 2 - o.center[1]) ** 2
            )
            assert o.id == before.id, (step, o, before)
        previous = objects
    seen = {o.id for o in first}
    blank = np.full_like(img, 255)
    for _ in range(8):  # everything leaves long enough to be forgotten
        assert pipeline.process("cam0", blank)[0] == []
    back, _ = pipeline.process("cam0", img)
    assert len(back) == len(first) and not ({o.id for o in back} & seen)


def test_tracker_keeps_an_object_through_a_short_gap():
    from services.vision.segment import Detection

    tr = Tracker(max_missed=3)
    a = Detection("object", "red", 0.9, (10, 10, 20, 20))
    ((id1, _),) = tr.update([a])
    tr.update([])
    tr.update([])
    ((id2, _),) = tr.update([Detection("object", "red", 0.9, (14, 12, 20, 20))])
    assert id1 == id2
    ((id3, _),) = tr.update([Detection("object", "blue", 0.9, (14, 12, 20, 20))])
    assert id3 != id1  # same place, other colour: another object


# -- the ONNX (YOLO) path, with a tiny model generated here -------------------------------------------


def planted(boxes: list[tuple[float, float, float, float, int, float]], classes: int = 3) -> np.ndarray:
    """cx, cy, w, h (letterboxed px), class, score -> a 1×(4+C)×N tensor."""
    pred = np.zeros((1, 4 + classes, len(boxes)), np.float32)
    for i, (cx, cy, w, h, cls, score) in enumerate(boxes):
        pred[0, :4, i] = (cx, cy, w, h)
        pred[0, 4 + cls, i] = score
    return pred


def test_letterbox_maps_a_wide_image_into_the_square_input():
    img = np.zeros((640, 1280, 3), np.uint8)
    tensor, lb = letterbox(img, 640)
    assert tensor.shape == (1, 3, 640, 640) and tensor.dtype == np.float32
    assert lb.scale == 0.5 and lb.pad_x == 0 and lb.pad_y == 160
    assert np.allclose(tensor[0, :, 0, 0], 114 / 255.0)  # padding is grey


def test_decode_undoes_the_letterbox_and_suppresses_duplicates():
    pred = planted(
        [
            (320, 320, 100, 50, 2, 0.9),  # kept
            (322, 321, 100, 50, 2, 0.8),  # same class, overlaps: suppressed
            (360, 320, 100, 50, 1, 0.7),  # other class, partly behind it (IoU 0.43): kept
            (321, 320, 100, 50, 0, 0.6),  # other class, the same box: one object with two labels, the best stays
            (100, 500, 40, 40, 0, 0.2),  # below the threshold
        ]
    )
    found = decode(pred, Letterbox(0.5, 0, 160), (1280, 640), conf_threshold=0.35, iou_threshold=0.45, classes=3)
    assert [(c, round(s, 2)) for c, s, _ in found] == [(2, 0.9), (1, 0.7)]
    assert np.allclose(found[0][2], (540, 270, 200, 100))
    transposed = decode(pred.transpose(0, 2, 1), Letterbox(0.5, 0, 160), (1280, 640), 0.35, 0.45, classes=3)
    assert [(c, s, tuple(b)) for c, s, b in transposed] == [(c, s, tuple(b)) for c, s, b in found]


def test_yolo_detector_runs_a_generated_model_end_to_end(tmp_path):
    img = photo("table.png")  # 506×460: scale 640/506, padded 29 px top and bottom
    scale = 640 / 506
    pad_y = round((640 - round(460 * scale)) / 2 - 0.1)

    def to_input(x, y, w, h):  # a box in table.png pixels -> centre/size in the model's letterboxed input
        return (x + w / 2) * scale, (y + h / 2) * scale + pad_y, w * scale, h * scale

    red_candy, blue_candy = (203, 296, 106, 103), (381, 30, 107, 107)  # where they are in the photo
    model = tmp_path / "tiny.onnx"
    tiny_yolo(
        model,
        planted(
            [
                (*to_input(*red_candy), 1, 0.9),
                (*to_input(red_candy[0] + 4, red_candy[1] - 3, 106, 103), 1, 0.7),  # a duplicate NMS must drop
                (*to_input(*blue_candy), 0, 0.6),
                (*to_input(20, 20, 40, 40), 2, 0.1),  # under the confidence threshold
            ]
        ),
    )
    detector = YoloDetector(str(model), names=("sports ball", "wine glass", "bottle"))
    found = detector.detect(img)
    assert [label for label, _, _ in found] == ["wine glass", "sports ball"]
    for (_, _, box), planted_box in zip(found, (red_candy, blue_candy)):
        assert np.allclose(box, planted_box, atol=1.0), (box, planted_box)
    objects, quality = VisionPipeline(detector).process("cam0", img)
    # labels through canonical_label (a COCO name stays itself: the parser names "wine glass" and "sports ball");
    # colour from each box's own pixels, so "the red glass" works with a DNN
    assert sorted((o.label, o.color) for o in objects) == [("sports ball", "blue"), ("wine glass", "red")]
    assert quality.sharpness > 0


def test_a_bad_model_path_is_a_clear_error(tmp_path):
    with pytest.raises(ModelError, match="not found"):
        YoloDetector(str(tmp_path / "missing.onnx"))
    junk = tmp_path / "junk.onnx"
    junk.write_bytes(b"not a model")
    with pytest.raises(ModelError, match="cannot load"):
        YoloDetector(str(junk))


def test_labels_file_maps_colours_to_language_classes(tmp_path):
    from services.vision.segment import read_labels

    assert read_labels(DATA / "demo" / "labels.json") == ({"*": "candy"}, [])
    good = tmp_path / "labels.json"
    good.write_text('{"red": "mug", "blue": "box", "*": "widget"}')
    labels, warnings = read_labels(good)
    assert labels == {"red": "cup", "blue": "box", "*": "widget"}  # "mug" is a cup to the language
    assert len(warnings) == 1 and "widget" in warnings[0]
    seg = ColorSegmenter(labels=labels)
    assert [seg.label_for(c) for c in ("red", "blue", "green")] == ["cup", "box", "widget"]
    for text, message in (('["red"]', "JSON object"), ('{"pink": "x"}', "not colours"), ("{", "not JSON")):
        bad = tmp_path / "bad.json"
        bad.write_text(text)
        with pytest.raises(ValueError, match=message):
            read_labels(bad)
    with pytest.raises(ValueError, match="cannot read"):
        read_labels(tmp_path / "missing.json")
