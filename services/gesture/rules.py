"""Gesture classes from the 21 hand landmarks of one frame — pure, rotation- and scale-invariant.

A finger is *extended* when its tip is farther from the wrist than its middle joint (PIP) and either far from
its knuckle (MCP) relative to the palm size or in a straight line with its joints (a hand tilted away from the
camera looks short but stays straight); *curled* when the tip is no farther from the wrist than the PIP, or
near the knuckle with the finger bent. All are ratios of distances, so a hand held sideways, pointing down or
at any distance from the camera gives the same answer — unlike the usual `tip.y < pip.y` rule, which only
works for an upright hand.

Classes (first match):
- `open_palm`: index, middle, ring and little finger extended (the stop sign);
- `point`: index out, the other three folded over (each tip no farther from the wrist than its middle joint),
  whatever the thumb does (raised or tucked) and from any side (palm, back, edge). "Index out" is an extended
  index, or — the finger aimed at the camera and foreshortened — a straight index whose tip is beyond its middle
  joint, at least `FORESHORTENED_REACH` palm sizes long. "Folded over" is stricter than curled: a relaxed or
  half-closed hand, whose other fingertips are still beyond their middle joints, is not a point; neither is a
  hand with any other finger extended (peace/V, rock, "call me");
- `thumbs_up`: all four curled, the thumb extended and pointing up in the image (within 50°);
- `fist`: all four curled, the thumb folded (its tip near the palm);
- None otherwise.
MediaPipe landmark order: 0 wrist; thumb 1–4; index 5–8; middle 9–12; ring 13–16; little 17–20.
"""

from __future__ import annotations

import math

import numpy as np

WRIST, THUMB_MCP, THUMB_IP, THUMB_TIP = 0, 2, 3, 4
INDEX_MCP, INDEX_TIP, MIDDLE_MCP, LITTLE_MCP = 5, 8, 9, 17
FINGERS = (5, 9, 13, 17)  # MCP of index, middle, ring, little; PIP = +1, TIP = +3

EXTENDED_REACH = 0.5  # |tip - MCP| / palm at least this: extended
CURLED_REACH = 0.45  # below this: curled
STRAIGHT = 0.9  # |tip - MCP| / length of its three bones: a straight finger...
SHORT_REACH = 0.3  # ...this long counts as extended too (a hand tilted away looks short, not bent)
TIP_BEYOND_PIP = 1.1  # |tip - wrist| / |PIP - wrist| at least this for an extended finger
FORESHORTENED_REACH = 0.2  # a straight index aimed at the camera may look this short and still point
THUMB_OUT = 0.65  # |thumb tip - index MCP| / palm at least this: thumb sticks out
THUMB_UP_DEG = 50.0
PALM_LENGTH_PER_WIDTH = 1.45


def palm_size(p: np.ndarray) -> float:
    """Palm length (wrist → middle MCP), or its width (index MCP → little MCP) × 1.45 if larger: a hand tilted
    away from the camera shortens one of them, rarely both (1.45 = length / width of the recorded real hands)."""
    length = float(np.linalg.norm(p[MIDDLE_MCP] - p[WRIST]))
    width = float(np.linalg.norm(p[LITTLE_MCP] - p[INDEX_MCP]))
    return max(length, PALM_LENGTH_PER_WIDTH * width) or 1.0


def finger_states(p: np.ndarray) -> list[str]:
    """'extended', 'curled' or 'unclear' for index, middle, ring, little."""
    palm = palm_size(p)
    states = []
    for mcp in FINGERS:
        tip_to_mcp = float(np.linalg.norm(p[mcp + 3] - p[mcp]))
        reach = tip_to_mcp / palm
        bones = sum(float(np.linalg.norm(p[mcp + i + 1] - p[mcp + i])) for i in range(3)) or 1.0
        straight = tip_to_mcp / bones  # 1 for a straight finger, however tilted: a line projects to a line
        beyond = float(np.linalg.norm(p[mcp + 3] - p[WRIST])) / (float(np.linalg.norm(p[mcp + 1] - p[WRIST])) or 1.0)
        if beyond >= TIP_BEYOND_PIP and (reach >= EXTENDED_REACH or (straight >= STRAIGHT and reach >= SHORT_REACH)):
            states.append("extended")
        elif beyond < 1.0 or (reach < CURLED_REACH and straight < STRAIGHT):
            states.append("curled")
        else:
            states.append("unclear")
    return states


def folded_over(p: np.ndarray, mcp: int) -> bool:
    """Is this finger folded back toward the palm: its tip no farther from the wrist than its middle joint (PIP)?
    A pointing hand's other fingers are; a relaxed hand's are not (their tips stay beyond the PIP)."""
    return float(np.linalg.norm(p[mcp + 3] - p[WRIST])) <= float(np.linalg.norm(p[mcp + 1] - p[WRIST]))


def index_out(p: np.ndarray, state: str) -> bool:
    """The index sticks out: extended, or straight and beyond its PIP but foreshortened (aimed at the camera)."""
    if state == "extended":
        return True
    mcp = INDEX_MCP
    palm = palm_size(p)
    tip_to_mcp = float(np.linalg.norm(p[mcp + 3] - p[mcp]))
    bones = sum(float(np.linalg.norm(p[mcp + i + 1] - p[mcp + i])) for i in range(3)) or 1.0
    beyond = float(np.linalg.norm(p[mcp + 3] - p[WRIST])) / (float(np.linalg.norm(p[mcp + 1] - p[WRIST])) or 1.0)
    return tip_to_mcp / bones >= STRAIGHT and beyond >= TIP_BEYOND_PIP and tip_to_mcp / palm >= FORESHORTENED_REACH


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
    if index_out(p, index) and all(folded_over(p, mcp) for mcp in FINGERS[1:]):
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
