"""estimate_view_poses: rendered views -> camera poses in the anchor's optical frame, end to end.

The predictor is the RenderOracle (the ideal denoiser of the rendered scene), so the true poses
are known. Reduced for speed: oracle grid every 10 deg at 16 px latents, 6 azimuth candidates,
probe batch 4, 3 adjustment steps, 150 refinement steps and 20 runner-up steps per view
(the paper: 8, 16, 10, 600; runner-up default 100), views preprocessed at 64 px.
"""
import threading

import numpy as np
import pytest
import torch

from idpose_core.cameras import opengl_to_optical, spherical_to_c2w
from idpose_core.pipeline import (
    BORDER_MARGIN_PX,
    PipelineSettings,
    ViewInput,
    estimate_view_poses,
    result_details,
    touches_border,
    views_mosaic,
)
from idpose_core.preprocessing import PreprocessingError
from idpose_core.solver import Cancelled, SolverConfig
from idpose_core.synthetic.render_oracle import RenderOracle
from idpose_core.synthetic.scenes import CAMERA_RADIUS, SceneRenderer, demo_objects

TRUE_SPH = np.array([[70.0, 20.0], [80.0, 110.0], [60.0, 230.0]])  # (polar, azimuth) deg of views 0..2
CONFIG = SolverConfig(azimuth_candidates=6, probe_batch=4, adjust_steps=3, adjust_lr=0.1, keep_top=2,
                      refine_steps_per_view=150, refine_lr=0.05, average_last=10,
                      runner_up_steps=20)
OBJECT_DISTANCE = 0.6  # metres: the published scale, unrelated to the render radius


@pytest.fixture(scope="module")
def scene():
    """Three rendered views (RGB on white, alpha from the mask) and the oracle that knows them."""
    spec = demo_objects()[0]
    sph = np.column_stack([np.radians(TRUE_SPH), np.full(len(TRUE_SPH), CAMERA_RADIUS)])
    with SceneRenderer(spec, image_size=96) as renderer:
        renders = [renderer.render(*pose) for pose in sph]
    oracle = RenderOracle(spec, sph, step_deg=10.0, latent_size=16, render_size=48)
    views = [ViewInput(rgb, (mask * 255).astype(np.uint8)) for rgb, mask in renders]
    settings = PipelineSettings(CONFIG.updated(anchor_polar_deg=float(np.degrees(sph[0, 0]))), OBJECT_DISTANCE,
                                image_size=64)
    return sph, oracle, views, settings


def true_poses(sph: np.ndarray) -> np.ndarray:
    """Ground truth: optical camera poses in the anchor's optical frame, scaled to OBJECT_DISTANCE."""
    world = opengl_to_optical(spherical_to_c2w(sph))
    poses = np.linalg.inv(world[0]) @ world
    poses[:, :3, 3] *= OBJECT_DISTANCE / sph[0, 2]
    return poses


def rotation_error_deg(a: np.ndarray, b: np.ndarray) -> float:
    cosine = (np.trace(a[:3, :3].T @ b[:3, :3]) - 1.0) / 2.0
    return float(np.degrees(np.arccos(np.clip(cosine, -1.0, 1.0))))


def test_rendered_views_come_back_as_their_true_poses_in_the_anchor_frame(scene):
    sph, oracle, views, settings = scene
    reports = []
    views = [views[0], ViewInput(views[1].rgb), views[2]]  # the middle one without alpha: its mask is computed
    result = estimate_view_poses(oracle, views, settings,
                                 progress=lambda stage, done, total: reports.append((stage, done, total)))
    assert result.poses.shape == (3, 4, 4)
    np.testing.assert_allclose(result.poses[0], np.eye(4), atol=1e-9)
    expected = true_poses(sph)
    for k in (1, 2):
        assert rotation_error_deg(result.poses[k], expected[k]) < 8.0, k
        assert np.linalg.norm(result.poses[k][:3, 3] - expected[k][:3, 3]) < 0.1 * OBJECT_DISTANCE, k
        np.testing.assert_allclose(result.poses[k][:3, :3] @ result.poses[k][:3, :3].T, np.eye(3), atol=1e-9)
    assert result.solver_result.rel_poses.shape == (2, 3)
    assert tuple(result.preprocessed.images.shape) == (3, 3, 64, 64)
    assert result.preprocessed.mask_methods[0] == "alpha" and result.preprocessed.mask_methods[2] == "alpha"
    assert result.preprocessed.mask_methods[1] != "alpha"
    stages = {stage for stage, _, _ in reports}
    assert {"exploration", "refinement"} <= stages, stages
    last = {stage: (done, total) for stage, done, total in reports}
    assert all(done == total > 0 for done, total in last.values()), last


def test_a_cancel_during_the_run_raises_cancelled(scene):
    _, oracle, views, settings = scene
    cancel = threading.Event()
    calls = []

    def progress(stage, done, total):
        calls.append(stage)
        if len(calls) == 3:
            cancel.set()

    with pytest.raises(Cancelled):
        estimate_view_poses(oracle, views, settings, progress=progress, cancel=cancel)
    assert len(calls) < 10, "stopped soon after the request"


def test_bad_view_sets_are_refused_with_the_problem_named(scene):
    _, oracle, views, settings = scene
    with pytest.raises(ValueError, match="at least 2 views"):
        estimate_view_poses(oracle, views[:1], settings)
    empty = ViewInput(views[1].rgb, np.zeros_like(views[1].alpha))
    with pytest.raises(PreprocessingError, match="view 1"):
        estimate_view_poses(oracle, [views[0], empty, views[2]], settings)


def shifted_left(view: ViewInput, pixels: int) -> ViewInput:
    """The view with its picture moved ``pixels`` to the left, white (and transparent) coming in on the right."""
    rgb, alpha = np.full_like(view.rgb, 255), np.zeros_like(view.alpha)
    rgb[:, :-pixels], alpha[:, :-pixels] = view.rgb[:, pixels:], view.alpha[:, pixels:]
    return ViewInput(rgb, alpha)


def test_a_view_cut_by_the_border_is_flagged_unreliable_and_a_centred_one_is_not(scene):
    _, oracle, views, settings = scene
    cols = np.flatnonzero(views[1].alpha.any(axis=0))
    cut = shifted_left(views[1], int(cols[0] + (cols[-1] - cols[0]) // 3))  # a third of the object off the frame
    result = estimate_view_poses(oracle, [views[0], cut, views[2]], settings)
    flags = [(view.touches_border, view.reliable) for view in result.views]
    assert flags[0] == (False, True) and flags[1] == (True, False)
    assert flags[2] == (False, not result.solver_result.ambiguous[1])
    assert [view["touches_border"] for view in result_details(result)["views"]] == [False, True, False]
    assert [mask.shape for mask in result.masks] == [view.rgb.shape[:2] for view in views]


def test_touching_the_border_allows_the_documented_margin():
    mask = np.zeros((40, 60), dtype=bool)
    mask[10:20, 20:30] = True
    assert not touches_border(mask)
    mask[25, BORDER_MARGIN_PX] = True  # within the margin of the left edge
    assert touches_border(mask)
    mask[25, BORDER_MARGIN_PX] = False
    mask[25, 59 - BORDER_MARGIN_PX - 1] = True  # one pixel further in from the right edge: clear of it
    assert not touches_border(mask)


def test_views_mosaic_puts_the_views_side_by_side_as_rgb8():
    images = torch.full((3, 3, 4, 4), -1.0)
    images[1] = 1.0
    images[2, 0] = 0.0  # red channel at mid-grey
    mosaic = views_mosaic(images)
    assert mosaic.shape == (4, 12, 3) and mosaic.dtype == np.uint8
    assert (mosaic[:, :4] == 0).all() and (mosaic[:, 4:8] == 255).all()
    assert (mosaic[:, 8:, 0] == 128).all() and (mosaic[:, 8:, 1:] == 0).all()
    with pytest.raises(ValueError, match=r"\(N, 3, S, S\)"):
        views_mosaic(torch.zeros(3, 4, 4))
