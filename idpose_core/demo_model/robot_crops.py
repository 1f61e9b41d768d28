"""What a robot's crop does to a clean render: the demo model's training augmentation for robot scenes.

A robot sees the object from farther or nearer than its partner view, under a white balance and exposure of its
own, with shadows cast across it, at a lower resolution and blurred, partly hidden by something in front or with
a neighbour taken into its mask, its mask's rim carrying a band of the table, or cut by the image border. Each
effect here is a pure function of an (S, S, 3) uint8 render on white and its (S, S) bool mask; ``robot_crop``
draws a random combination of them, with a ``Tone`` (white balance, exposure, gamma) that the views of one scene
share. The textures it paints (rims, occluders) are random colour fields, not the
scenes' own textures, so that training does not learn the test scenes' tables.
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from idpose_core.preprocessing import bounding_box


@dataclass(frozen=True)
class CropAugmentation:
    """How often each effect is applied to a view (``clean``: the share left exactly as rendered) and its range."""

    clean: float = 0.4
    scale: float = 0.3
    scale_range: tuple[float, float] = (0.85, 1.2)  # zoom about the object: a camera nearer or farther
    colour: float = 0.8
    shadow: float = 0.35
    shadow_strength: tuple[float, float] = (0.45, 0.8)  # brightness left in the shadow
    blur: float = 0.5
    resolution: tuple[float, float] = (0.3, 1.0)  # of the render's size, before scaling back up
    occluder: float = 0.15
    rim: float = 0.25
    rim_px: tuple[int, int] = (1, 4)
    border: float = 0.1
    border_cut: tuple[float, float] = (0.1, 0.35)  # of the object's extent lost past the border
    noise: float = 0.3
    noise_sd: tuple[float, float] = (2.0, 6.0)  # grey levels


@dataclass(frozen=True)
class Tone:
    """A camera's colour rendering: per-channel ``gains`` (3,) (white balance times exposure), then ``gamma``."""

    gains: tuple[float, float, float]
    gamma: float


def random_tone(rng: np.random.Generator) -> Tone:
    """Exposure 0.7-1.3, white balance within about 8 % per channel, gamma 0.8-1.25."""
    gains = rng.uniform(0.7, 1.3) * rng.normal(1.0, 0.08, size=3)
    return Tone(tuple(float(g) for g in gains), float(rng.uniform(0.8, 1.25)))


def colour_field(rng: np.random.Generator, size: int) -> np.ndarray:
    """A random smooth colour texture (size, size, 3) uint8 with fine grain: a stand-in for any surface."""
    coarse = rng.uniform(0, 255, size=(int(rng.integers(2, 9)),) * 2 + (3,)).astype(np.float32)
    field = cv2.resize(coarse, (size, size), interpolation=cv2.INTER_CUBIC)
    field += rng.normal(0.0, rng.uniform(2.0, 20.0), size=field.shape).astype(np.float32)
    return np.clip(field, 0, 255).astype(np.uint8)


def _box_edges(mask: np.ndarray) -> tuple[int, int, int, int]:
    """(top, bottom, left, right) of the mask's pixels, bottom and right exclusive (``bounding_box`` as edges)."""
    x, y, width, height = bounding_box(mask)
    return y, y + height, x, x + width


def zoom(rgb: np.ndarray, mask: np.ndarray, factor: float) -> tuple[np.ndarray, np.ndarray]:
    """Scale the image by ``factor`` about the mask's centre (white fills what comes in from outside)."""
    rows, cols = np.nonzero(mask)
    centre = (float(cols.mean()), float(rows.mean()))
    matrix = cv2.getRotationMatrix2D(centre, 0.0, factor)
    size = rgb.shape[1], rgb.shape[0]
    warped = cv2.warpAffine(rgb, matrix, size, flags=cv2.INTER_LINEAR, borderValue=(255, 255, 255))
    warped_mask = cv2.warpAffine(mask.astype(np.uint8), matrix, size, flags=cv2.INTER_NEAREST) > 0
    return warped, warped_mask


def recolour(rgb: np.ndarray, tone: Tone) -> np.ndarray:
    """The image as a camera of ``tone`` renders it."""
    scaled = np.clip(rgb.astype(np.float32) * np.asarray(tone.gains, np.float32) / 255.0, 0.0, 1.0)
    return (255.0 * scaled ** tone.gamma).astype(np.uint8)


def cast_shadow(rgb: np.ndarray, mask: np.ndarray, rng: np.random.Generator, strength: float) -> np.ndarray:
    """Darken the object to ``strength`` on one side of a random soft-edged line through the middle of its box."""
    top, bottom, left, right = _box_edges(mask)
    angle = rng.uniform(0.0, 2.0 * np.pi)
    normal = np.array([np.cos(angle), np.sin(angle)])
    width, height = right - left, bottom - top
    point = np.array([rng.uniform(left + width / 4, right - width / 4),
                      rng.uniform(top + height / 4, bottom - height / 4)])
    ys, xs = np.mgrid[0:rgb.shape[0], 0:rgb.shape[1]]
    signed = (xs - point[0]) * normal[0] + (ys - point[1]) * normal[1]
    softness = rng.uniform(1.0, 0.15 * max(bottom - top, right - left) + 1.0)
    shade = 1.0 - (1.0 - strength) / (1.0 + np.exp(-signed / softness))
    out = rgb.astype(np.float32)
    out[mask] *= shade[mask][:, None]
    return out.astype(np.uint8)


def degrade(rgb: np.ndarray, resolution: float, sigma: float) -> np.ndarray:
    """Lose resolution (down to ``resolution`` of the size and back) and blur by ``sigma`` px."""
    size = rgb.shape[1], rgb.shape[0]
    small = max(4, int(round(size[0] * resolution)))
    out = cv2.resize(cv2.resize(rgb, (small, small), interpolation=cv2.INTER_AREA), size,
                     interpolation=cv2.INTER_LINEAR)
    return cv2.GaussianBlur(out, (0, 0), sigma) if sigma > 0.1 else out


def occlude(rgb: np.ndarray, mask: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """An ellipse on the object's outline: either something in front that the mask leaves out (a hole, white),
    or a neighbour the mask takes in (painted with a random texture and added to the mask)."""
    top, bottom, left, right = _box_edges(mask)
    edge = np.argwhere(mask & ~cv2.erode(mask.astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool))
    y, x = edge[int(rng.integers(len(edge)))]
    extent = max(bottom - top, right - left)
    axes = tuple(max(2, int(extent * rng.uniform(0.1, 0.3))) for _ in range(2))
    blob = np.zeros(mask.shape, np.uint8)
    cv2.ellipse(blob, (int(x), int(y)), axes, float(rng.uniform(0, 180)), 0, 360, 1, -1)
    blob = blob.astype(bool)
    if rng.random() < 0.5:
        remaining = mask & ~blob
        return (rgb, remaining) if remaining.sum() > 0.5 * mask.sum() else (rgb, mask)
    out = rgb.copy()
    out[blob] = colour_field(rng, mask.shape[0])[blob]
    return out, mask | blob


def rim(rgb: np.ndarray, mask: np.ndarray, rng: np.random.Generator, pixels: int) -> tuple[np.ndarray, np.ndarray]:
    """A mask ``pixels`` too wide, its rim showing a random background, or ``pixels`` too narrow."""
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * pixels + 1,) * 2)
    if rng.random() < 0.5:
        eroded = cv2.erode(mask.astype(np.uint8), kernel).astype(bool)
        return (rgb, eroded) if eroded.sum() > 0.5 * mask.sum() else (rgb, mask)
    grown = cv2.dilate(mask.astype(np.uint8), kernel).astype(bool)
    out = rgb.copy()
    band = grown & ~mask
    out[band] = colour_field(rng, mask.shape[0])[band]
    return out, grown


def border_cut(mask: np.ndarray, rng: np.random.Generator, share: float) -> np.ndarray:
    """The mask with ``share`` of its extent on one random side cut off, as by the image border."""
    top, bottom, left, right = _box_edges(mask)
    out = mask.copy()
    side = int(rng.integers(4))
    if side == 0:
        out[:top + int(share * (bottom - top))] = False
    elif side == 1:
        out[bottom - int(share * (bottom - top)):] = False
    elif side == 2:
        out[:, :left + int(share * (right - left))] = False
    else:
        out[:, right - int(share * (right - left)):] = False
    return out if out.sum() > 0.4 * mask.sum() else mask


def robot_crop(rgb: np.ndarray, mask: np.ndarray, rng: np.random.Generator,
               augmentation: CropAugmentation = CropAugmentation(), tone: Tone | None = None
               ) -> tuple[np.ndarray, np.ndarray]:
    """A random robot's version of a clean view: (rgb (S, S, 3) uint8 on white, mask (S, S) bool). ``tone``: the
    scene's camera tone, applied with ``augmentation.colour``'s odds (None: drawn here)."""
    a = augmentation
    if not mask.any() or rng.random() < a.clean:
        return rgb, mask
    if rng.random() < a.scale:
        rgb, mask = zoom(rgb, mask, float(rng.uniform(*a.scale_range)))
        if not mask.any():
            return rgb, mask
    if rng.random() < a.rim:
        rgb, mask = rim(rgb, mask, rng, int(rng.integers(a.rim_px[0], a.rim_px[1] + 1)))
    if rng.random() < a.occluder:
        rgb, mask = occlude(rgb, mask, rng)
    if rng.random() < a.colour:
        rgb = recolour(rgb, tone or random_tone(rng))
    if rng.random() < a.shadow:
        rgb = cast_shadow(rgb, mask, rng, float(rng.uniform(*a.shadow_strength)))
    if rng.random() < a.blur:
        rgb = degrade(rgb, float(rng.uniform(*a.resolution)), float(rng.uniform(0.0, 1.2)))
    if rng.random() < a.noise:
        noisy = rgb.astype(np.float32) + rng.normal(0.0, rng.uniform(*a.noise_sd), size=rgb.shape)
        rgb = np.clip(noisy, 0, 255).astype(np.uint8)
    if rng.random() < a.border:
        mask = border_cut(mask, rng, float(rng.uniform(*a.border_cut)))
    out = rgb.copy()
    out[~mask] = 255
    return out, mask
