"""The sphere warp of the reference: rotations, visibility and the direction content moves with the pose."""
from __future__ import annotations

import math

import pytest
import torch

from idpose_core.demo_model.reference_warp import camera_rotation, sphere_warp

SIZE, RADIUS = 32, 0.6


def pixel_u() -> torch.Tensor:
    """Normalised horizontal coordinate (S,) of each column's centre, -1 left to +1 right."""
    return (2 * torch.arange(SIZE, dtype=torch.float32) + 1) / SIZE - 1


def stripe(at_u: float) -> torch.Tensor:
    """A (1, 3, S, S) image, zero but for a bright vertical stripe at horizontal coordinate ``at_u``."""
    image = torch.zeros(1, 3, SIZE, SIZE)
    image[..., (pixel_u() - at_u).abs() < 0.07] = 1.0
    return image


def test_camera_rotations_are_proper_and_look_at_the_origin():
    polar, azimuth = torch.tensor([0.3, math.pi / 2, 2.5]), torch.tensor([0.0, 1.0, -2.0])
    rotation = camera_rotation(polar, azimuth)
    assert torch.allclose(rotation.transpose(1, 2) @ rotation, torch.eye(3).expand(3, 3, 3), atol=1e-6)
    assert torch.allclose(torch.linalg.det(rotation), torch.ones(3), atol=1e-6)
    centre = torch.stack([torch.sin(polar) * torch.cos(azimuth), torch.sin(polar) * torch.sin(azimuth),
                          torch.cos(polar)], -1)
    assert torch.allclose(rotation[..., 2], centre, atol=1e-6)  # the back axis points at the camera
    assert (rotation[..., 2, 1] > 0).all()  # world up is up in the image


def test_no_pose_change_keeps_the_reference_on_the_sphere_and_a_half_turn_sees_nothing():
    reference = torch.rand(1, 3, SIZE, SIZE)
    same = sphere_warp(reference, torch.zeros(1, 3), RADIUS)
    visible = same[:, 3:]
    disk = math.pi * RADIUS ** 2 / 4  # the sphere's share of the [-1, 1]^2 frame
    assert float(visible.mean()) == pytest.approx(disk, rel=0.05)
    assert torch.allclose(same[:, :3], reference * visible, atol=1e-5)
    opposite = sphere_warp(reference, torch.tensor([[0.0, math.pi, 0.0]]), RADIUS)
    assert float(opposite[:, 3].mean()) < 0.02 * disk
    quarter = sphere_warp(reference, torch.tensor([[0.0, math.pi / 2, 0.0]]), RADIUS)
    assert float(quarter[:, 3].mean()) == pytest.approx(disk / 2, rel=0.15)


def test_turning_towards_the_right_brings_the_right_side_to_the_middle():
    """The camera moving to larger azimuth moves towards the reference image's right (the world's +y for a camera
    on +x): the object's right side turns to face it, so content right of centre moves left."""
    warped = sphere_warp(stripe(0.4), torch.tensor([[0.0, 0.3, 0.0]]), RADIUS)
    columns = warped[0, 0].sum(0)
    centroid = float((columns * pixel_u()).sum() / columns.sum())
    assert 0.0 < centroid < 0.3
    lower = sphere_warp(stripe(0.0).transpose(2, 3), torch.tensor([[0.3, 0.0, 0.0]]), RADIUS)
    rows = lower[0, 0].sum(1)  # a horizontal stripe at the centre; the camera drops below the equator
    image_v = -pixel_u()  # rows go down
    assert float((rows * image_v).sum() / rows.sum()) > 0.05  # what faced the camera is now seen from below: higher


def test_the_warp_is_differentiable_in_the_pose_and_checks_its_shapes():
    pose = torch.tensor([[0.1, 0.4, 0.0]], requires_grad=True)
    sphere_warp(stripe(0.2), pose, RADIUS)[:, :3].sum().backward()
    assert pose.grad is not None and float(pose.grad[0, 1].abs()) > 0
    with pytest.raises(ValueError, match="need references"):
        sphere_warp(torch.zeros(1, 3, SIZE, SIZE), torch.zeros(2, 3), RADIUS)
