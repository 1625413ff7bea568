"""The overlays of a camera, drawn with OpenCV (for `hri view --snapshot`).

The page (static/view.js) draws the same layers, in the same order and colours, on a canvas; both take the
overlay map of `ViewState.overlay`. Each layer is one function so a new one (the body skeleton once the
gesture service publishes it) is one more entry in LAYERS.
"""

from __future__ import annotations

from typing import Any, Callable

import cv2
import numpy as np

# BGR. The same colours as static/view.css / view.js (kept in one table there too).
BOX = (80, 220, 0)  # detection boxes
TARGET = (255, 0, 255)  # the target of the latest command: magenta, a colour scenes rarely have
CANDIDATE = (0, 165, 255)  # candidates of a clarification question: orange
HAND = (255, 255, 0)  # hand skeleton: cyan
RAY = (0, 255, 255)  # pointing ray: yellow
PERSON = (255, 160, 60)  # person boxes: light blue
SPEAKER = (60, 60, 255)  # the person speaking: red
TEXT_BG = (0, 0, 0)

HAND_CONNECTIONS = (
    (0, 1),
    (1, 2),
    (2, 3),
    (3, 4),
    (0, 5),
    (5, 6),
    (6, 7),
    (7, 8),
    (5, 9),
    (9, 10),
    (10, 11),
    (11, 12),
    (9, 13),
    (13, 14),
    (14, 15),
    (15, 16),
    (13, 17),
    (17, 18),
    (18, 19),
    (19, 20),
    (0, 17),
)


def _pt(p: list[float]) -> tuple[int, int]:
    return int(round(p[0])), int(round(p[1]))


def _label(img: np.ndarray, text: str, x: float, y: float, colour: tuple[int, int, int]) -> None:
    font, scale, thick = cv2.FONT_HERSHEY_SIMPLEX, 0.5, 1
    (w, h), base = cv2.getTextSize(text, font, scale, thick)
    x0, y0 = max(0, min(int(x), img.shape[1] - w - 4)), max(int(y) - h - base - 2, 0)
    cv2.rectangle(img, (x0, y0), (x0 + w + 4, y0 + h + base + 2), TEXT_BG, -1)
    cv2.putText(img, text, (x0 + 2, y0 + h + 1), font, scale, colour, thick, cv2.LINE_AA)


def _box(img: np.ndarray, bbox: list[float], colour: tuple[int, int, int], thickness: int) -> None:
    x, y, w, h = bbox
    cv2.rectangle(img, _pt([x, y]), _pt([x + w, y + h]), colour, thickness)


def object_name(obj: dict[str, Any]) -> str:
    return " ".join(p for p in (obj.get("color"), obj["label"]) if p)


def object_position(obj: dict[str, Any]) -> str:
    """' (x, y, z) m' in the camera's optical frame when depth gave the object a position, else ''."""
    p = obj.get("position")
    return f" ({p[0]:+.2f}, {p[1]:+.2f}, {p[2]:.2f}) m" if p else ""


def draw_objects(img: np.ndarray, layers: dict[str, Any]) -> None:
    # the decision layer labels its own objects (target, candidates): no second label under theirs
    decided = {o["id"] for o in [layers.get("target"), *layers.get("candidates", [])] if o}
    for obj in layers.get("objects", []):
        _box(img, obj["bbox"], BOX, 2)
        if obj["id"] not in decided:
            _label(
                img,
                f"{object_name(obj)} {obj['id']} {obj['score']:.2f}{object_position(obj)}",
                obj["bbox"][0],
                obj["bbox"][1],
                BOX,
            )


def draw_hands(img: np.ndarray, layers: dict[str, Any]) -> None:
    h, w = img.shape[:2]
    for hand in layers.get("hands", []):
        pts = hand["landmarks"]
        for a, b in HAND_CONNECTIONS:
            cv2.line(img, _pt(pts[a]), _pt(pts[b]), HAND, 2, cv2.LINE_AA)
        for p in pts:
            cv2.circle(img, _pt(p), 3, HAND, -1, cv2.LINE_AA)
        ray = hand.get("ray")
        if ray:
            draw_ray(img, ray, w + h)
        if hand.get("gesture"):
            _label(img, f"{hand['hand']} {hand['gesture']}", pts[0][0], pts[0][1] + 20, HAND)


def draw_persons(img: np.ndarray, layers: dict[str, Any]) -> None:
    """Each person's box and id; the speaker's box thicker, in red, labelled as speaking."""
    for person in layers.get("persons", []):
        speaking = person.get("speaker")
        colour = SPEAKER if speaking else PERSON
        _box(img, person["bbox"], colour, 3 if speaking else 1)
        hands = ",".join(person.get("hands") or [])
        text = person["id"] + (" speaking" if speaking else "") + (f" hands {hands}" if hands else "")
        _label(img, text + object_position(person), person["bbox"][0], person["bbox"][1] + 18, colour)


def draw_ray(img: np.ndarray, ray: dict[str, Any], length: float) -> None:
    (ox, oy), (dx, dy) = ray["origin"], ray["direction"]
    cv2.arrowedLine(img, _pt([ox, oy]), _pt([ox + dx * length, oy + dy * length]), RAY, 2, cv2.LINE_AA, tipLength=0.02)


def draw_decision(img: np.ndarray, layers: dict[str, Any]) -> None:
    for cand in layers.get("candidates", []):
        _box(img, cand["bbox"], CANDIDATE, 3)
        _label(img, f"? {object_name(cand)} {cand['id']}", cand["bbox"][0], cand["bbox"][1], CANDIDATE)
    target = layers.get("target")
    if target:
        _box(img, target["bbox"], TARGET, 4)
        cx, cy = _pt(target["center"])
        cv2.drawMarker(img, (cx, cy), TARGET, cv2.MARKER_CROSS, 18, 3)
        _label(
            img,
            f"{target.get('intent', 'target')}: {object_name(target)} {target['id']}{object_position(target)}",
            target["bbox"][0],
            target["bbox"][1],
            TARGET,
        )
    loc = layers.get("location")
    if loc:
        cv2.drawMarker(img, _pt([loc["x"], loc["y"]]), TARGET, cv2.MARKER_TILTED_CROSS, 24, 3)


def draw_quality(img: np.ndarray, layers: dict[str, Any]) -> None:
    q = layers.get("quality")
    if q:
        _label(
            img,
            f"brightness {q['brightness']:.2f}  contrast {q['contrast']:.2f}  sharpness {q['sharpness']:.2f}",
            4,
            img.shape[0] - 4,
            (255, 255, 255),
        )


def colourize_depth(metres: np.ndarray) -> np.ndarray:
    """BGR picture of a depth image in metres (NaN = none): near red, far blue (over the 2nd–98th
    percentile of the valid depths, OpenCV jet), no measurement black."""
    valid = np.isfinite(metres)
    out = np.zeros((*metres.shape, 3), np.uint8)
    if not valid.any():
        return out
    near, far = np.percentile(metres[valid], [2, 98])
    scaled = np.clip((far - np.where(valid, metres, far)) / max(far - near, 1e-3), 0.0, 1.0)
    out[:] = cv2.applyColorMap((scaled * 255).astype(np.uint8), cv2.COLORMAP_JET)
    out[~valid] = 0
    return out


# bottom to top: the decision is drawn last so it is never hidden
LAYERS: tuple[Callable[[np.ndarray, dict[str, Any]], None], ...] = (
    draw_persons,
    draw_objects,
    draw_hands,
    draw_decision,
    draw_quality,
)


def render(image: np.ndarray, layers: dict[str, Any]) -> np.ndarray:
    """A copy of the BGR `image` with every overlay layer drawn on it."""
    out = image.copy()
    for layer in LAYERS:
        layer(out, layers)
    return out
