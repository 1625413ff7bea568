"""Gesture classes from the 21 hand landmarks of one frame — pure, rotation- and scale-invariant.

A finger is *extended* when its tip is far from its knuckle (MCP) relative to the palm (wrist → middle MCP)
and farther from the wrist than its middle joint (PIP); *curled* otherwise. Both are ratios of distances, so a
hand held sideways, pointing down or at any distance from the camera gives the same answer — unlike the
usual `tip.y < pip.y` rule, which only works for an upright hand.

Classes (first match):
- `open_palm`: index, middle, ring and little finger extended (the stop sign);
- `point`: index extended, the other three curled;
- `thumbs_up`: all four curled, the thumb extended and pointing up in the image (within 50°);
- `fist`: all four curled, the thumb folded (its tip near the palm);
- None otherwise.
MediaPipe landmark order: 0 wrist; thumb 1–4; index 5–8; middle 9–12; ring 13–16; little 17–20.
"""

from __future__ import annotations

import math

import numpy as np

WRIST, THUMB_MCP, THUMB_IP, THUMB_TIP = 0, 2, 3, 4
INDEX_MCP, INDEX_TIP, MIDDLE_MCP = 5, 8, 9
FINGERS = (5, 9, 13, 17)  # MCP of index, middle, ring, little; PIP = +1, TIP = +3

EXTENDED_REACH = 0.5     # |tip - MCP| / palm at least this: extended
CURLED_REACH = 0.45      # below this: curled
TIP_BEYOND_PIP = 1.1     # |tip - wrist| / |PIP - wrist| at least this for an extended finger
THUMB_OUT = 0.65         # |thumb tip - index MCP| / palm at least this: thumb sticks out
THUMB_UP_DEG = 50.0


def palm_size(p: np.ndarray) -> float:
    return float(np.linalg.norm(p[MIDDLE_MCP] - p[WRIST])) or 1.0


def finger_states(p: np.ndarray) -> list[str]:
    """'extended', 'curled' or 'unclear' for index, middle, ring, little."""
    palm = palm_size(p)
    states = []
    for mcp in FINGERS:
        reach = float(np.linalg.norm(p[mcp + 3] - p[mcp])) / palm
        beyond = float(np.linalg.norm(p[mcp + 3] - p[WRIST])) / (float(np.linalg.norm(p[mcp + 1] - p[WRIST])) or 1.0)
        if reach >= EXTENDED_REACH and beyond >= TIP_BEYOND_PIP:
            states.append("extended")
        elif reach < CURLED_REACH or beyond < 1.0:
            states.append("curled")
        else:
            states.append("unclear")
    return states


def thumb_out(p: np.ndarray) -> bool:
    return float(np.linalg.norm(p[THUMB_TIP] - p[INDEX_MCP])) / palm_size(p) >= THUMB_OUT


def thumb_points_up(p: np.ndarray) -> bool:
    d = p[THUMB_TIP] - p[THUMB_MCP]
    norm = float(np.linalg.norm(d))
    if norm == 0:
        return False
    angle = math.degrees(math.acos(max(-1.0, min(1.0, -d[1] / norm))))  # image y grows downwards
    return angle <= THUMB_UP_DEG


def classify(landmarks: np.ndarray | list) -> str | None:
    """The gesture shown by one hand's 21 [x, y] landmarks in this frame, or None."""
    p = np.asarray(landmarks, dtype=float).reshape(21, 2)
    index, middle, ring, little = finger_states(p)
    others = (middle, ring, little)
    if index == "extended" and all(s == "extended" for s in others):
        return "open_palm"
    if index == "extended" and all(s == "curled" for s in others):
        return "point"
    if index == "curled" and all(s == "curled" for s in others):
        if thumb_out(p):
            return "thumbs_up" if thumb_points_up(p) else None
        return "fist"
    return None


def pointing_ray(p: np.ndarray | list) -> tuple[tuple[float, float], tuple[float, float]]:
    """Origin (index MCP) and unit direction (MCP → tip) of the index finger, in image pixels."""
    q = np.asarray(p, dtype=float).reshape(21, 2)
    d = q[INDEX_TIP] - q[INDEX_MCP]
    norm = float(np.linalg.norm(d)) or 1.0
    return (float(q[INDEX_MCP, 0]), float(q[INDEX_MCP, 1])), (float(d[0] / norm), float(d[1] / norm))
