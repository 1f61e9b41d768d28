"""The depth cut's confidence in its mask, on surfaces with known geometry, and what an unsure mask costs a view:
it is never reliable and stays out of the object's cloud."""
from __future__ import annotations

import math

import numpy as np

from idpose_core.depth_fusion import ViewRefinement
from idpose_core.pipeline import ViewReport, mask_trusted, with_refinement
from idpose_core.segmentation.confidence import mask_confidence

SIZE = 160
BOX = (slice(60, 100), slice(60, 100))
BAND = 48 * 48 - 44 * 44  # the readings 2 to 4 px outside the 40 px box
TOP_BAND = 2 * 40  # its two rows right above the box


def scene(wall_gap: float) -> tuple[np.ndarray, np.ndarray]:
    """Points (H, W, 3) of a box's face 0.5 m away (the box of pixels ``BOX``), the room 0.5 m behind it but right
    above the box, where a wall stands ``wall_gap`` m behind the face; and the box's mask."""
    rows, cols = np.indices((SIZE, SIZE))
    points = np.stack([(cols - 80.0) / 200.0, (rows - 80.0) / 200.0, np.full((SIZE, SIZE), 1.0)], axis=-1)
    mask = np.zeros((SIZE, SIZE), bool)
    mask[BOX] = True
    points[mask, 2] = 0.5
    points[:60, 60:100, 2] = 0.5 + wall_gap
    return points, mask


EVERYWHERE = np.ones((SIZE, SIZE), bool)


def test_an_object_apart_from_everything_around_it_is_sure():
    points, mask = scene(0.5)
    assert mask_confidence(mask, points, EVERYWHERE, EVERYWHERE) == 1.0


def test_a_wall_just_behind_the_object_lowers_it_by_the_share_of_the_outline_it_touches():
    points, mask = scene(0.01)
    assert math.isclose(mask_confidence(mask, points, EVERYWHERE, EVERYWHERE), 1.0 - TOP_BAND / BAND)
    table = EVERYWHERE.copy()
    table[:60] = False  # the same readings on the table: apart, whatever their distance
    assert mask_confidence(mask, points, EVERYWHERE, table) == 1.0
    unread = EVERYWHERE.copy()
    unread[:60] = False  # no readings there: nothing to judge, the rest is apart
    assert mask_confidence(mask, points, unread, unread) == 1.0
    rim = EVERYWHERE.copy()
    rim[:58] = False  # only the two rows next to the box stand out: its own edge, which the band skips
    assert mask_confidence(mask, points, EVERYWHERE, rim) == 1.0


def verified(margin: float = 2.0) -> ViewRefinement:
    return ViewRefinement(True, "", 0.9, 0.002, 5.0, 0.01, "registration", margin, False, False, math.nan)


def report(confidence: float) -> ViewReport:
    return ViewReport("depth", "", None, None, 0.5, touches_border=False, reliable=True, mask_confidence=confidence)


def test_a_pose_on_an_unsure_mask_is_never_reliable():
    assert with_refinement(report(0.9), verified(), 0.5).reliable
    assert not with_refinement(report(0.3), verified(), 0.5).reliable
    assert mask_trusted(math.nan, 0.5), "a mask another method made is not judged here"
    assert not mask_trusted(0.49, 0.5) and mask_trusted(0.5, 0.5)
