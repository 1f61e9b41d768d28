"""The masks' second pass across views, on rendered views with their true poses: a part one view's mask lost comes
back from the others' cloud (not the table under it), and a view left out of the fusion loses the wall its mask
took in; a view not posed keeps its mask."""
from __future__ import annotations

import math

import numpy as np
import pytest

from idpose_core.depth_fusion import cross_view_masks, fused_cloud, view_cloud
from idpose_core.preprocessing import mask_iou
from idpose_core.synthetic.robot_views import pinhole_intrinsics
from idpose_core.synthetic.scenes import demo_objects
from idpose_core.synthetic.tabletop import TabletopRenderer, challenge_camera, random_layout
from idpose_core.view_input import ViewInput

SIZE, FOV = 160, 60.0
K = pinhole_intrinsics(SIZE, FOV)
VOXEL = 0.005


@pytest.fixture(scope="module")
def views():
    """Three views of the lego brick on its table, 35 deg apart (views, true masks, poses in the anchor's frame)."""
    lego = next(spec for spec in demo_objects() if spec.name == "lego")
    layout = random_layout(lego, np.random.default_rng(4), behind_azimuth=0.0)
    cameras = [challenge_camera(np.array([math.radians(65.0), math.radians(azimuth), 0.5]))
               for azimuth in (0.0, 35.0, -35.0)]
    with TabletopRenderer(layout, SIZE, FOV) as renderer:
        frames = [renderer.render(camera) for camera in cameras]
    poses = np.stack([np.linalg.inv(cameras[0]) @ camera for camera in cameras])
    return [ViewInput(f.rgb, depth=f.depth, intrinsics=K) for f in frames], [f.target_mask for f in frames], poses


def cloud_of(views, masks, poses, which):
    return fused_cloud([view_cloud(views[k], masks[k]) for k in which], [poses[k] for k in which], VOXEL).points


def test_a_part_one_view_lost_comes_back_from_the_others_cloud(views):
    views, truth, poses = views
    rows = np.nonzero(truth[1].any(axis=1))[0]
    cut = truth[1].copy()
    cut[: rows[0] + (rows[-1] - rows[0]) // 3] = False  # the top third lost: a head dropped against a wall
    masks = [truth[0], cut, truth[2]]
    done = cross_view_masks(views, masks, poses, cloud_of(views, masks, poses, (0, 2)), VOXEL, [True] * 3, [True] * 3)
    before, after = mask_iou(cut, truth[1]), mask_iou(done[1].mask, truth[1])
    assert before < 0.8 and after > 0.9, "what the other views saw of the top comes back (its edges they saw less)"
    assert done[1].added > 0 and done[1].removed == 0
    assert (done[1].mask & ~truth[1]).sum() < 0.01 * truth[1].sum(), "not the table under the brick"
    for k in (0, 2):  # the others, whole already, take in nothing but a few pixels of their own edge
        assert mask_iou(done[k].mask, truth[k]) > mask_iou(truth[k], truth[k]) - 0.02


def test_a_view_left_out_of_the_fusion_loses_what_lies_beyond_the_object(views):
    views, truth, poses = views
    wall = truth[1].copy()
    rows = np.nonzero(truth[1].any(axis=1))[0]
    wall[: rows[0]] = True  # the room above the brick taken in
    masks = [truth[0], wall, truth[2]]
    cloud = cloud_of(views, masks, poses, (0, 2))
    kept_out = cross_view_masks(views, masks, poses, cloud, VOXEL, [True] * 3, [True, False, True])[1]
    assert mask_iou(wall, truth[1]) < 0.5 and mask_iou(kept_out.mask, truth[1]) > 0.9 and kept_out.removed > 0
    fused = cross_view_masks(views, masks, poses, cloud, VOXEL, [True] * 3, [True] * 3)[1]
    assert fused.removed == 0, "a view in the fusion is only grown"
    unposed = cross_view_masks(views, masks, poses, cloud, VOXEL, [True, False, True], [True, False, True])[1]
    assert np.array_equal(unposed.mask, wall) and unposed.added == unposed.removed == 0
