"""The robot-crop augmentation: each effect does what it says to a view and its mask."""
from __future__ import annotations

import numpy as np
import pytest

from idpose_core.demo_model.robot_crops import (
    CropAugmentation,
    Tone,
    border_cut,
    cast_shadow,
    degrade,
    occlude,
    recolour,
    rim,
    robot_crop,
    zoom,
)


@pytest.fixture
def view() -> tuple[np.ndarray, np.ndarray]:
    """A 64 px textured square object (20..44) on white."""
    rng = np.random.default_rng(0)
    rgb = np.full((64, 64, 3), 255, np.uint8)
    mask = np.zeros((64, 64), bool)
    mask[20:44, 20:44] = True
    rgb[mask] = rng.integers(60, 200, size=(int(mask.sum()), 3))
    return rgb, mask


def test_zoom_scales_the_object_about_its_centre(view):
    rgb, mask = view
    _, grown = zoom(rgb, mask, 1.25)
    assert grown.sum() == pytest.approx(1.25 ** 2 * mask.sum(), rel=0.1)
    rows, cols = np.nonzero(grown)
    assert rows.mean() == pytest.approx(31.5, abs=1) and cols.mean() == pytest.approx(31.5, abs=1)


def test_recolour_applies_gains_per_channel(view):
    rgb, _ = view
    out = recolour(rgb, Tone((1.2, 1.0, 0.8), 1.0))
    assert out[..., 0].mean() > rgb[..., 0].mean() and out[..., 2].mean() < rgb[..., 2].mean()
    assert np.abs(out[..., 1].astype(int) - rgb[..., 1]).max() <= 1


def test_a_shadow_darkens_part_of_the_object_only(view):
    rgb, mask = view
    out = cast_shadow(rgb, mask, np.random.default_rng(1), 0.5)
    assert np.array_equal(out[~mask], rgb[~mask])
    ratio = out[mask].astype(float).mean(axis=1) / rgb[mask].astype(float).mean(axis=1)
    assert ratio.min() < 0.65 and ratio.max() > 0.85  # one side dark, the other lit


def test_degrading_loses_detail(view):
    rgb, _ = view
    out = degrade(rgb, 0.25, 1.0)
    assert out.shape == rgb.shape
    assert np.abs(np.diff(out.astype(float), axis=1)).mean() < 0.5 * np.abs(np.diff(rgb.astype(float), axis=1)).mean()


def test_an_occluder_cuts_a_hole_or_is_taken_into_the_mask(view):
    rgb, mask = view
    outcomes = set()
    for seed in range(20):
        out, changed = occlude(rgb, mask, np.random.default_rng(seed))
        if changed.sum() < mask.sum():
            assert not (changed & ~mask).any()
            outcomes.add("hole")
        elif changed.sum() > mask.sum():
            added = changed & ~mask
            assert (changed & mask).sum() == mask.sum() and not np.array_equal(out[added], rgb[added])
            outcomes.add("taken in")
    assert outcomes == {"hole", "taken in"}


def test_a_rim_widens_the_mask_with_background_or_narrows_it(view):
    rgb, mask = view
    sizes = {int(rim(rgb, mask, np.random.default_rng(seed), 2)[1].sum()) for seed in range(10)}
    assert min(sizes) < mask.sum() < max(sizes)


def test_a_border_cut_removes_one_side(view):
    _, mask = view
    cut = border_cut(mask, np.random.default_rng(3), 0.25)
    assert not (cut & ~mask).any()
    assert cut.sum() == pytest.approx(0.75 * mask.sum(), rel=0.05)
    rows, cols = np.nonzero(cut)
    assert (rows.max() - rows.min() + 1, cols.max() - cols.min() + 1) in ((18, 24), (24, 18))


def test_robot_crop_is_seeded_leaves_a_clean_share_and_paints_the_background_white(view):
    rgb, mask = view
    first = [robot_crop(rgb, mask, np.random.default_rng(seed)) for seed in range(40)]
    again = [robot_crop(rgb, mask, np.random.default_rng(seed)) for seed in range(40)]
    assert all(np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1]) for a, b in zip(first, again))
    clean = sum(np.array_equal(out, rgb) and np.array_equal(m, mask) for out, m in first)
    assert 8 <= clean <= 25  # the clean share is 0.4
    assert all((out[~m] == 255).all() for out, m in first)
    never = CropAugmentation(clean=1.0)
    assert all(np.array_equal(robot_crop(rgb, mask, np.random.default_rng(s), never)[0], rgb) for s in range(5))
