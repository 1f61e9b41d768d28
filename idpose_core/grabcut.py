"""GrabCut from a label image, keeping the object's connected part: the step both segmenters end with."""
from __future__ import annotations

import cv2
import numpy as np


def grabcut_object(rgb: np.ndarray, labels: np.ndarray, iterations: int) -> np.ndarray:
    """The object (H, W) bool after ``iterations`` of GrabCut on ``rgb`` (H, W, 3) from ``labels`` (H, W) of
    ``cv2.GC_*`` values: of GrabCut's foreground, the connected part (8-connected) holding most sure-object
    labels. The caller seeds OpenCV's RNG (``cv2.setRNGSeed``) for a repeatable answer."""
    sure = labels == cv2.GC_FGD
    labels = labels.copy()
    cv2.grabCut(np.ascontiguousarray(rgb), labels, None, np.zeros((1, 65)), np.zeros((1, 65)), iterations,
                cv2.GC_INIT_WITH_MASK)
    foreground = np.isin(labels, (cv2.GC_FGD, cv2.GC_PR_FGD)).astype(np.uint8)
    _, components = cv2.connectedComponents(foreground, connectivity=8)
    sure_per_component = np.bincount(components[sure], minlength=components.max() + 1)
    sure_per_component[0] = 0
    return components == int(np.argmax(sure_per_component))
