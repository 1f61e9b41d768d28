"""Views -> Zero-1-to-3 inputs, as the paper prepares them: object on white, one shared square window, 256 px.

The foreground mask of a view comes from the most trusted source it has: an external segmentation
``mask``, else its alpha channel, else its depth image (the object standing on its support plane,
``idpose_core.segmentation``, boundary settled by GrabCut), else its background colour when the
image border is near-uniform (thresholding), else OpenCV GrabCut seeded with the pixels whose colours
are least like the border's, weighted towards the image centre (a cluttered photo is assumed to have
the object roughly in the middle). One square window serves the whole set (the largest mask bounding
box side times ``window_scale``), so every view keeps the same scale; it is centred on each view's
object and padded with white where it leaves the image. A view whose mask cannot be an object the
model can compare (none found, nearly the whole frame, or a speck) is refused by one plausibility rule,
``check_object_mask``, wherever views are prepared.
"""
from __future__ import annotations

import math
import threading
from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np
import torch

from idpose_core.cancellation import raise_if_cancelled
from idpose_core.grabcut import grabcut_object
from idpose_core.segmentation import DepthSegmentationError, depth_cut
from idpose_core.view_input import ViewInput, ViewInputError

WHITE = (255, 255, 255)
ALPHA_THRESHOLD = 127  # alpha above this is object
BORDER_FRACTION = 0.03  # border band used to learn the background, as a fraction of the shorter side
UNIFORM_TOLERANCE = 8.0  # CIE Lab Delta E from the border's median colour that counts as background
UNIFORM_SHARE = 0.6  # this share of the border within tolerance -> near-uniform (objects may touch the edge)
FOREGROUND_CONTRAST = 20.0  # Delta E from the background colour that counts as object
SPECK_FRACTION = 0.05  # thresholded components smaller than this share of the largest are noise
GRABCUT_SIDE = 320  # GrabCut works on the view scaled to this longer side
GRABCUT_ITERATIONS = 5
BORDER_COLOURS = 8  # k-means clusters summarising the border's colours
CENTRE_SIGMA = 1.0 / 3.0  # centre prior width, as a fraction of the image side
WINDOW_SCALE = 1.5  # the square window around the object, as a multiple of its box's larger side
SURE_OBJECT_SCORE = 0.5  # seed score (of the maximum) above which a pixel is surely object
SURE_OBJECT_SHARE = 0.002  # of the pixels: fewer sure-object seeds than this and nothing stands out (noise)
# The plausibility rule for an object mask (``check_object_mask``): Zero-1-to-3 compares whole objects
# seen with a margin of background, so a view must show one of a size the model can see.
MIN_IMAGE_SIDE = 32  # px: a smaller image holds too little of any object
MIN_OBJECT_SIDE = 16  # px: the object's bounding box must be at least this long on its longer side
MAX_OBJECT_SHARE = 0.9  # of the frame: a mask this large is background, or an object without a margin


class PreprocessingError(ValueError):
    """A view cannot be prepared (bad array, or no plausible object found); the message names the view."""


@dataclass(frozen=True)
class PreprocessedViews:
    """``images`` (N, 3, size, size) float32 in [-1, 1]; ``masks`` N bool (H_i, W_i) input-resolution
    foreground masks; ``mask_methods`` N of ``MASK_METHODS``; ``mask_notes`` N of "" or why a more trusted
    source could not be used (e.g. the depth found no support plane); ``windows`` N (x, y, side) square crops
    in input pixels (may extend past the image, padded white); ``mask_confidences`` N of the depth cut's confidence
    in its mask (``ForegroundMask``; NaN for other methods)."""

    images: torch.Tensor
    masks: list[np.ndarray]
    mask_methods: list[str]
    mask_notes: list[str]
    windows: list[tuple[int, int, int]]
    mask_confidences: list[float]


def _lab(rgb: np.ndarray) -> np.ndarray:
    """RGB uint8 (H, W, 3) -> CIE Lab float32 (L in [0, 100]) so distances are Delta E."""
    return cv2.cvtColor(rgb.astype(np.float32) / 255.0, cv2.COLOR_RGB2LAB)


def _border_band(shape: tuple[int, int]) -> np.ndarray:
    """Bool (H, W), True on the outer band of width BORDER_FRACTION of the shorter side (at least 2 px)."""
    height, width = shape
    band = np.zeros((height, width), dtype=bool)
    width_px = max(2, int(round(BORDER_FRACTION * min(height, width))))
    band[:width_px], band[-width_px:], band[:, :width_px], band[:, -width_px:] = True, True, True, True
    return band


def _drop_specks(mask: np.ndarray) -> np.ndarray:
    """Keep the connected components of at least SPECK_FRACTION of the largest one's area."""
    count, labels, stats, _ = cv2.connectedComponentsWithStats(mask.astype(np.uint8), connectivity=8)
    if count <= 1:
        return mask
    areas = stats[1:, cv2.CC_STAT_AREA]
    kept = np.flatnonzero(areas >= SPECK_FRACTION * areas.max()) + 1
    return np.isin(labels, kept)


def threshold_mask(rgb: np.ndarray) -> np.ndarray | None:
    """Object mask (H, W) bool against a near-uniform background (its colour: the border median), else None."""
    lab = _lab(cv2.medianBlur(rgb, 3))  # median: drops sensor noise, keeps the object's edges in place
    band = _border_band(rgb.shape[:2])
    background = np.median(lab[band], axis=0)
    distance = np.linalg.norm(lab - background, axis=-1)
    if np.mean(distance[band] <= UNIFORM_TOLERANCE) < UNIFORM_SHARE:
        return None
    mask = (distance > FOREGROUND_CONTRAST).astype(np.uint8)
    mask = cv2.morphologyEx(mask, cv2.MORPH_OPEN, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (3, 3)))
    return _drop_specks(mask.astype(bool))


def _grabcut_seeds(small_rgb: np.ndarray) -> np.ndarray:
    """GrabCut mask (h, w) uint8: border = background, distinctive central colours = (probable) object."""
    lab = cv2.GaussianBlur(_lab(small_rgb), (0, 0), 2.0)
    band = _border_band(small_rgb.shape[:2])
    criteria = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 20, 1.0)
    _, _, colours = cv2.kmeans(lab[band], BORDER_COLOURS, None, criteria, 3, cv2.KMEANS_PP_CENTERS)
    distinctiveness = np.min(np.linalg.norm(lab[:, :, None, :] - colours[None, None], axis=-1), axis=-1)
    height, width = band.shape
    rows, cols = np.mgrid[0:height, 0:width]
    offsets = ((cols - width / 2) / (CENTRE_SIGMA * width)) ** 2 + ((rows - height / 2) / (CENTRE_SIGMA * height)) ** 2
    score = np.where(band, 0.0, distinctiveness * np.exp(-0.5 * offsets))
    score8 = np.round(255.0 * score / max(float(score.max()), 1e-12)).astype(np.uint8)
    otsu, _ = cv2.threshold(score8, 0, 255, cv2.THRESH_BINARY + cv2.THRESH_OTSU)
    seeds = np.full(band.shape, cv2.GC_PR_BGD, dtype=np.uint8)
    seeds[score8 > otsu] = cv2.GC_PR_FGD
    # Surely object: a high score and a colour that really differs from every border colour (not in noise).
    seeds[(score8 >= max(otsu, 255 * SURE_OBJECT_SCORE)) & (distinctiveness > FOREGROUND_CONTRAST)] = cv2.GC_FGD
    seeds[band] = cv2.GC_BGD
    return seeds


def grabcut_mask(rgb: np.ndarray) -> np.ndarray:
    """Object mask (H, W) bool of a cluttered photo: GrabCut at GRABCUT_SIDE px, the component with most sure seeds.

    Seeds OpenCV's random generator (k-means and GrabCut's GMMs) so the same photo gives the same mask.
    """
    height, width = rgb.shape[:2]
    scale = min(1.0, GRABCUT_SIDE / max(height, width))
    small = cv2.resize(rgb, (max(1, round(width * scale)), max(1, round(height * scale))), interpolation=cv2.INTER_AREA)
    cv2.setRNGSeed(0)
    seeds = _grabcut_seeds(small)
    if np.mean(seeds == cv2.GC_FGD) < SURE_OBJECT_SHARE:  # nothing stands out from the border: no object
        return np.zeros((height, width), dtype=bool)
    mask = grabcut_object(small, seeds, GRABCUT_ITERATIONS).astype(np.float32)
    return cv2.resize(mask, (width, height), interpolation=cv2.INTER_LINEAR) >= 0.5


def alpha_mask(alpha: np.ndarray | None) -> np.ndarray | None:
    """The object mask an alpha channel carries, or None when there is none (no alpha, or fully opaque)."""
    if alpha is None:
        return None
    mask = alpha > ALPHA_THRESHOLD
    return None if mask.all() else mask


MASK_METHODS = ("mask", "alpha", "depth", "threshold", "grabcut")  # most trusted first


@dataclass(frozen=True)
class ForegroundMask:
    """A view's object ``mask`` (H, W) bool, the ``method`` that made it (``MASK_METHODS``), a ``note`` (why depth,
    when present, was not used, or what its cut is unsure of; "" otherwise) and the depth cut's ``confidence`` (how
    separable the object is from what was left out, ``segmentation.mask_confidence``; NaN for other methods)."""

    mask: np.ndarray
    method: str
    note: str = ""
    confidence: float = math.nan


def foreground_mask(view: ViewInput) -> ForegroundMask:
    """The object's mask from the most trusted source the view has (``MASK_METHODS``).

    An alpha channel counts only when it marks something transparent; depth needs ``depth`` and ``intrinsics``.
    """
    if view.mask is not None:
        return ForegroundMask(np.asarray(view.mask, dtype=bool), "mask")
    mask = alpha_mask(view.alpha)
    if mask is not None:
        return ForegroundMask(mask, "alpha")
    note = ""
    if view.depth is not None:
        try:
            cut = depth_cut(view)
            return ForegroundMask(cut.mask, "depth", cut.note, cut.confidence)
        except DepthSegmentationError as err:
            note = f"depth not used: {err}"
    mask = threshold_mask(view.rgb)
    if mask is not None:
        return ForegroundMask(mask, "threshold", note)
    return ForegroundMask(grabcut_mask(view.rgb), "grabcut", note)


def on_white(rgb: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """RGB uint8 (H, W, 3) with white outside the object mask (a hard cut: some alpha channels offset their values)."""
    return np.where(mask[..., None], rgb, np.uint8(255))


def bounding_box(mask: np.ndarray) -> tuple[int, int, int, int]:
    """(x, y, width, height) of the True pixels of a non-empty mask."""
    return cv2.boundingRect(mask.astype(np.uint8))


def mask_iou(mask: np.ndarray, truth: np.ndarray) -> float:
    """Intersection over union of two bool masks of one shape (1.0 when both are empty)."""
    union = np.logical_or(mask, truth).sum()
    return float(np.logical_and(mask, truth).sum() / union) if union else 1.0


def square_window(mask: np.ndarray, side: int) -> tuple[int, int, int]:
    """(x, y, side) of the square of ``side`` px centred on the mask's bounding box."""
    x, y, width, height = bounding_box(mask)
    return int(round(x + (width - side) / 2)), int(round(y + (height - side) / 2)), side


def crop_padded(image: np.ndarray, window: tuple[int, int, int]) -> np.ndarray:
    """The ``window`` (x, y, side) of ``image`` (H, W, 3), padded with white where it leaves the image."""
    x, y, side = window
    height, width = image.shape[:2]
    top, left = max(0, -y), max(0, -x)
    bottom, right = max(0, y + side - height), max(0, x + side - width)
    padded = cv2.copyMakeBorder(image, top, bottom, left, right, cv2.BORDER_CONSTANT, value=WHITE)
    return padded[y + top : y + top + side, x + left : x + left + side]


def check_view(view: ViewInput, name: str = "view 0") -> None:
    """``PreprocessingError`` (naming ``name``) unless the view's arrays fit together (``ViewInput.check``) and
    its image is at least MIN_IMAGE_SIDE a side."""
    try:
        view.check(name)
    except ViewInputError as err:
        raise PreprocessingError(str(err)) from None
    if min(view.rgb.shape[:2]) < MIN_IMAGE_SIDE:
        raise PreprocessingError(f"{name} is {view.rgb.shape[1]}x{view.rgb.shape[0]} px, too small (at least "
                                 f"{MIN_IMAGE_SIDE} px a side)")


def check_object_mask(mask: np.ndarray, method: str, name: str = "view 0") -> None:
    """The plausibility rule: ``PreprocessingError`` unless ``mask`` shows one object the model can compare.

    Refused: an empty mask (no object found), a mask covering more than MAX_OBJECT_SHARE of the frame
    (no object separated from the background), and an object under MIN_OBJECT_SIDE px on its longer side.
    """
    if not mask.any():
        raise PreprocessingError(f"{name}: no object found (empty {method} mask)")
    share = float(np.mean(mask))
    if share > MAX_OBJECT_SHARE:
        raise PreprocessingError(f"{name}: the {method} mask covers {share:.0%} of the frame (at most "
                                 f"{MAX_OBJECT_SHARE:.0%}): no object separated from its background")
    _, _, width, height = bounding_box(mask)
    if max(width, height) < MIN_OBJECT_SIDE:
        raise PreprocessingError(f"{name}: the object ({method} mask) is only {width}x{height} px, too small to "
                                 f"compare (at least {MIN_OBJECT_SIDE} px on its longer side)")


def precheck_view(view: ViewInput, name: str = "view 0") -> None:
    """The checks that need no mask computation, cheap enough for every captured image: the arrays, the
    image size and, when an external mask or the alpha channel carries the object, its plausibility.
    ``preprocess_views`` applies them all again, and the plausibility rule to computed masks as well."""
    check_view(view, name)
    if view.mask is not None:
        check_object_mask(np.asarray(view.mask, dtype=bool), "mask", name)
    elif (mask := alpha_mask(view.alpha)) is not None:
        check_object_mask(mask, "alpha", name)


def preprocess_views(views: Sequence[ViewInput], size: int = 256, window_scale: float = WINDOW_SCALE,
                     cancel: threading.Event | None = None) -> PreprocessedViews:
    """N views -> ``PreprocessedViews`` of (N, 3, size, size): masked to white, one window for all, resized.

    Raises ``PreprocessingError`` naming the view for a malformed array or an implausible object mask
    (``check_object_mask``), and ``Cancelled`` when ``cancel`` is set (checked before each view's mask).
    """
    if len(views) == 0:
        raise PreprocessingError("no views to preprocess")
    if size < 1 or not window_scale > 0:
        raise PreprocessingError(f"size must be >= 1 and window_scale > 0, got {size} and {window_scale}")
    found = []
    for index, view in enumerate(views):
        check_view(view, f"view {index}")
        raise_if_cancelled(cancel, f"preprocessing view {index}")
        found.append(foreground_mask(view))
        check_object_mask(found[-1].mask, found[-1].method, f"view {index}")
    masks = [item.mask for item in found]
    largest_side = max(max(bounding_box(mask)[2:]) for mask in masks)
    side = max(1, int(round(largest_side * window_scale)))
    windows, crops = [], []
    for view, mask in zip(views, masks):
        window = square_window(mask, side)
        crop = crop_padded(on_white(view.rgb, mask), window)
        crops.append(cv2.resize(crop, (size, size), interpolation=cv2.INTER_AREA))
        windows.append(window)
    pixels = torch.from_numpy(np.stack(crops)).permute(0, 3, 1, 2).float()
    return PreprocessedViews(pixels / 127.5 - 1.0, masks, [item.method for item in found],
                             [item.note for item in found], windows, [item.confidence for item in found])
