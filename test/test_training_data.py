"""Training pairs of the embedded model: sources drawn by weight, only views the pipeline accepts."""
from __future__ import annotations

import numpy as np
import pytest
import torch
import torch.nn.functional as F

from idpose_core.demo_model.training_data import PairPool, PairSource, RenderedViews, random_pairs


def rendered(objects: int, views: int, colour: int, size: int = 48) -> RenderedViews:
    """Flat squares of one grey level on white, a camera per view; an object-sized mask in every view."""
    rgb = np.full((objects, views, size, size, 3), 255, np.uint8)
    mask = np.zeros((objects, views, size, size), bool)
    rgb[:, :, 12:36, 12:36] = colour
    mask[:, :, 12:36, 12:36] = True
    azimuths = np.broadcast_to(np.linspace(0.5, 2.5, views), (objects, views))
    cameras = np.stack([np.full((objects, views), np.pi / 2), azimuths, np.full((objects, views), 2.0)], -1)
    return RenderedViews(rgb, mask, cameras, tuple(f"o{k}" for k in range(objects)))


def downsample(images: torch.Tensor) -> torch.Tensor:
    return F.interpolate(images, size=(16, 16), mode="area")


def test_pairs_come_from_the_sources_by_weight():
    dark, light = rendered(2, 4, 20), rendered(2, 4, 200)
    pool = PairPool([PairSource(dark, weight=0.8), PairSource(light, weight=0.2)], downsample, capacity=400,
                    refresh=1, window_scale_range=(1.5, 1.5))
    pool.fill(np.random.default_rng(0), 400)
    reference = pool.tensors["reference"]
    dark_share = float((reference.flatten(1).min(1).values < -0.5).float().mean())
    assert dark_share == pytest.approx(0.8, abs=0.07)
    reference, target, pose = pool.draw(np.random.default_rng(1), 8)
    assert reference.shape == target.shape == (8, 3, 16, 16) and pose.shape == (8, 3)


def test_a_view_the_pipeline_refuses_is_never_drawn():
    views = rendered(1, 3, 50)
    views.mask[0, 1] = False  # an empty mask: no object found
    assert views.usable.tolist() == [[True, False, True]]
    objects, reference, target = random_pairs(views, np.random.default_rng(0), 50)
    assert set(reference) | set(target) == {0, 2} and (reference != target).all()


def test_bad_sources_name_the_problem():
    with pytest.raises(ValueError, match="at least one source"):
        PairPool([], downsample, 8, 1, (1.5, 1.5))
    with pytest.raises(ValueError, match="positive sum"):
        PairPool([PairSource(rendered(1, 2, 50), weight=0.0)], downsample, 8, 1, (1.5, 1.5))
    broken = rendered(1, 2, 50)
    broken.mask[0, 0] = False
    with pytest.raises(ValueError, match="no object has two views"):
        random_pairs(broken, np.random.default_rng(0), 1)
