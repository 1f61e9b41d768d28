"""Turn a view upright: rotate its images about the principal point so that world up points up in them.

The rotation about the optical axis is a pure camera rotation, so it is exact for every pixel (no depth
needed): pixel ``u`` of the real camera lands at ``K' rz(roll) K^-1 u`` in the upright one. The canvas
grows to hold the whole rotated image (``K'`` is ``K`` shifted by the margin); colour borders are
mirrored from the image (so a background stays background), masks and depth get "nothing" there.
"""
from __future__ import annotations

import math
from dataclasses import replace

import cv2
import numpy as np

from idpose_core.gravity import roll_angle, rz
from idpose_core.view_input import ViewInput

MIN_ROLL = math.radians(0.1)  # below this a view is used as it is


def intrinsics_or_default(view: ViewInput) -> np.ndarray:
    """The view's K, else one with the principal point at the image centre and square pixels (only the
    principal point and the focal ratio matter for a turn about the optical axis)."""
    if view.intrinsics is not None:
        return np.asarray(view.intrinsics, dtype=np.float64)
    cx, cy = view.principal_point()
    return np.array([[1.0, 0.0, cx], [0.0, 1.0, cy], [0.0, 0.0, 1.0]])


def _warp(image: np.ndarray | None, matrix: np.ndarray, size: tuple[int, int], nearest: bool,
          border: int, value: float = 0) -> np.ndarray | None:
    if image is None:
        return None
    source = image.astype(np.uint8) if image.dtype == np.bool_ else image
    warped = cv2.warpAffine(source, matrix, size, flags=cv2.INTER_NEAREST if nearest else cv2.INTER_LINEAR,
                            borderMode=border, borderValue=value)
    return warped.astype(bool) if image.dtype == np.bool_ else warped


def upright_warp(view: ViewInput, roll: float) -> tuple[np.ndarray, np.ndarray, tuple[int, int]]:
    """(the turn by ``roll`` about the principal point (3, 3, pixels to pixels), the shift (3, 3) that moves the
    turned image onto the upright canvas, the canvas (width, height)); the canvas holds the whole turned image."""
    k = intrinsics_or_default(view)
    turn = k @ rz(roll) @ np.linalg.inv(k)  # affine: a turn about z keeps the third coordinate
    height, width = view.rgb.shape[:2]
    corners = np.array([[0, 0, 1], [width - 1, 0, 1], [0, height - 1, 1], [width - 1, height - 1, 1]], float)
    moved = corners @ turn.T
    low, high = np.floor(moved[:, :2].min(axis=0)), np.ceil(moved[:, :2].max(axis=0))
    shift = np.array([[1.0, 0.0, -low[0]], [0.0, 1.0, -low[1]], [0.0, 0.0, 1.0]])
    return turn, shift, (int(high[0] - low[0]) + 1, int(high[1] - low[1]) + 1)


def upright_view(view: ViewInput) -> tuple[ViewInput, float]:
    """(the view turned upright, its roll in radians); a view without ``gravity_up`` or with a negligible
    roll comes back as it is, with roll 0."""
    if view.gravity_up is None:
        return view, 0.0
    roll = roll_angle(view.gravity_up)
    if abs(roll) < MIN_ROLL:
        return view, roll
    turn, shift, size = upright_warp(view, roll)
    full = shift @ turn
    matrix = full[:2]
    depth = None if view.depth is None else np.nan_to_num(view.depth, nan=0.0)
    roi = None
    if view.roi is not None:
        x, y, w, h = view.roi
        box = np.array([[x, y, 1], [x + w, y, 1], [x, y + h, 1], [x + w, y + h, 1]], float) @ full.T
        (x0, y0), (x1, y1) = np.floor(box[:, :2].min(axis=0)), np.ceil(box[:, :2].max(axis=0))
        roi = (int(x0), int(y0), int(x1 - x0), int(y1 - y0))
    upright = replace(
        view,
        rgb=_warp(view.rgb, matrix, size, False, cv2.BORDER_REFLECT_101),
        alpha=_warp(view.alpha, matrix, size, True, cv2.BORDER_CONSTANT),
        mask=_warp(view.mask, matrix, size, True, cv2.BORDER_CONSTANT),
        depth=_warp(depth, matrix, size, True, cv2.BORDER_CONSTANT),
        intrinsics=None if view.intrinsics is None else shift @ intrinsics_or_default(view),
        gravity_up=rz(roll) @ np.asarray(view.gravity_up, dtype=np.float64),
        roi=roi,
    )
    return upright, roll


def original_frame_mask(mask: np.ndarray, view: ViewInput, roll: float) -> np.ndarray:
    """A bool mask on ``view``'s upright canvas (``upright_view``) mapped back to the view's own pixels
    (H, W); a view used as it is (no gravity, or a negligible roll) keeps its mask."""
    if view.gravity_up is None or abs(roll) < MIN_ROLL:
        return mask
    turn, shift, _ = upright_warp(view, roll)
    height, width = view.rgb.shape[:2]
    back = cv2.warpAffine(mask.astype(np.uint8), (shift @ turn)[:2], (width, height),
                          flags=cv2.INTER_NEAREST | cv2.WARP_INVERSE_MAP, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    return back.astype(bool)
