"""Build the demo's camera scenes from the shipped real photos (run once; the results are committed).

- table.png: a crop of OpenCV's smarties.png, enlarged 2x: one red, one orange, two green, two blue candies.
- pointing.png: OpenCV's handSrc.jpg (a real hand lying on a table) with the middle, ring and little fingers
  removed by inpainting, so the hand points with its index finger; two candies cut from smarties.png are
  pasted on the table: a red one on the line of the index finger, a blue one off it.
- stop.png: OpenCV's Histogram_Comparison_Source_1.jpg (a real open palm), enlarged 2x.

No real photo of a pointing hand ships in any package this project may use, hence the edit; see
data/ATTRIBUTION.md. Needs mediapipe (to place the fingers): python scripts/make_demo_scenes.py
"""

from __future__ import annotations

from pathlib import Path

import cv2
import mediapipe as mp
import numpy as np

ROOT = Path(__file__).resolve().parent.parent
HTML = Path("/usr/share/doc/opencv-doc/opencv4/html")
OUT = ROOT / "data" / "demo"


def landmarks(img: np.ndarray) -> np.ndarray:
    with mp.solutions.hands.Hands(static_image_mode=True, max_num_hands=1, model_complexity=1) as hands:
        res = hands.process(cv2.cvtColor(img, cv2.COLOR_BGR2RGB))
    if not res.multi_hand_landmarks:
        raise SystemExit("no hand found")
    return np.array([[p.x * img.shape[1], p.y * img.shape[0]] for p in res.multi_hand_landmarks[0].landmark])


def cut_candy(smarties: np.ndarray, center: tuple[int, int], r: int = 30) -> tuple[np.ndarray, np.ndarray]:
    x, y = center
    patch = smarties[y - r : y + r, x - r : x + r].copy()
    hsv = cv2.cvtColor(patch, cv2.COLOR_BGR2HSV)
    mask = ((hsv[..., 1] > 90) & (hsv[..., 2] > 40)).astype(np.uint8) * 255
    mask = cv2.morphologyEx(mask, cv2.MORPH_OPEN, np.ones((3, 3), np.uint8))
    n, labels, stats, _ = cv2.connectedComponentsWithStats(mask)
    biggest = 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
    return patch, (labels == biggest).astype(np.uint8) * 255


def paste(dst: np.ndarray, patch: np.ndarray, mask: np.ndarray, center: tuple[int, int]) -> None:
    h, w = mask.shape
    x0, y0 = center[0] - w // 2, center[1] - h // 2
    roi = dst[y0 : y0 + h, x0 : x0 + w]
    soft = cv2.GaussianBlur(mask, (5, 5), 0)[..., None] / 255.0
    roi[:] = (patch * soft + roi * (1 - soft)).astype(np.uint8)


def main() -> None:
    OUT.mkdir(parents=True, exist_ok=True)
    smarties = cv2.imread(str(ROOT / "data" / "images" / "tabletop" / "smarties.png"))
    table = cv2.resize(smarties[40:270, 160:413], None, fx=2, fy=2, interpolation=cv2.INTER_CUBIC)
    cv2.imwrite(str(OUT / "table.png"), table)

    hand = cv2.imread(str(HTML / "handSrc.jpg"))
    p = landmarks(hand)
    mask = np.zeros(hand.shape[:2], np.uint8)
    # wide strokes from just above the knuckles to past the tips: narrower ones leave enough finger for
    # MediaPipe to see the fingers as still extended (checked with the lite and the full model)
    width = int(1.3 * np.linalg.norm(p[5] - p[9]))
    for mcp, tip in ((9, 12), (13, 16), (17, 20)):
        start = p[mcp] + 0.3 * (p[mcp + 1] - p[mcp])
        end = p[tip] + 0.8 * (p[tip] - p[tip - 1])
        cv2.line(mask, tuple(map(int, start)), tuple(map(int, end)), 255, width)
    pointing = cv2.inpaint(hand, mask, 7, cv2.INPAINT_TELEA)
    q = landmarks(pointing)
    direction = (q[8] - q[5]) / np.linalg.norm(q[8] - q[5])
    on_ray = q[8] + direction * 75
    normal = np.array([-direction[1], direction[0]])
    off_ray = q[8] + direction * 20 + normal * 190
    for (cx, cy), where in (((288, 212), on_ray), ((347, 237), off_ray)):
        patch, m = cut_candy(smarties, (cx, cy))
        paste(pointing, patch, m, (int(where[0]), int(where[1])))
    cv2.imwrite(str(OUT / "pointing.png"), pointing)

    palm = cv2.imread(str(HTML / "Histogram_Comparison_Source_1.jpg"))
    cv2.imwrite(str(OUT / "stop.png"), cv2.resize(palm, None, fx=2, fy=2, interpolation=cv2.INTER_CUBIC))
    print(f"wrote {', '.join(sorted(p.name for p in OUT.glob('*.png')))} to {OUT}")


if __name__ == "__main__":
    main()
