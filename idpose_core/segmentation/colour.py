"""Colour as the depth cut compares it: chromaticity, which a lamp's brightness and shading leave alone, so that
two faces of one object match and two objects of different colours do not."""
from __future__ import annotations

import numpy as np

OBJECT_CHROMA_DELTA = 0.04  # between the median chromaticities (r, g, b) / (r + g + b) of two regions: more, and they
# are two objects' (two faces of one object under a lamp differ only in brightness)


def chromaticity(rgb: np.ndarray) -> np.ndarray:
    """(H, W, 3) float: each pixel's (r, g, b) / (r + g + b), with 1 added to each channel (black stays defined)."""
    chroma = rgb.astype(np.float64) + 1.0
    return chroma / chroma.sum(axis=-1, keepdims=True)


def median_chromaticity(chroma: np.ndarray, region: np.ndarray) -> np.ndarray:
    """(3,): the median chromaticity of ``chroma`` (``chromaticity``) over ``region`` (H, W) bool."""
    return np.median(chroma[region], axis=0)


def same_colour(first: np.ndarray, second: np.ndarray) -> bool:
    """Whether two median chromaticities (``median_chromaticity``) lie within ``OBJECT_CHROMA_DELTA``."""
    return bool(np.linalg.norm(first - second) <= OBJECT_CHROMA_DELTA)
