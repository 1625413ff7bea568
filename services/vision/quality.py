"""How far a frame can be trusted, as three numbers in 0–1 (published in Detections.quality).

- brightness = mean grey level / 255: the plain exposure; a dark frame is near 0. A bright frame is not
  penalised here (a white table is bright and fine); a blown-out one shows as low contrast.
- contrast = standard deviation of the grey levels / 64, capped at 1: a flat, washed-out or black frame is low.
- sharpness = 1 − exp(−var(Laplacian) / 150): a focused frame is near 1, a blurred one near 0.
Measured on the grey image scaled to 320 px wide, so the figures do not depend on the camera's resolution.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

GOOD_STD = 64.0
SHARP_LAPLACIAN_VAR = 150.0
WIDTH = 320


def image_quality(bgr: np.ndarray) -> tuple[float, float, float]:
    grey = cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY)
    if grey.shape[1] != WIDTH:
        grey = cv2.resize(
            grey, (WIDTH, max(1, round(grey.shape[0] * WIDTH / grey.shape[1]))), interpolation=cv2.INTER_AREA
        )
    mean, std = cv2.meanStdDev(grey)
    lap_var = float(cv2.Laplacian(grey, cv2.CV_64F).var())
    brightness = float(mean[0, 0]) / 255.0
    contrast = min(1.0, float(std[0, 0]) / GOOD_STD)
    sharpness = 1.0 - math.exp(-lap_var / SHARP_LAPLACIAN_VAR)
    return round(brightness, 4), round(contrast, 4), round(sharpness, 4)
