"""The depth cut, the pipeline of the steps in the modules beside it: the object on a table, cut out with an
aligned depth image and no learnt weights.

Back-project the depth with the intrinsics, find the support plane by RANSAC (the largest plane whose
normal points up: along gravity when it is known, else towards the top of the image), keep what
stands above it, split that into connected pieces at depth jumps (an object in front of another is a
different piece) and at concave folds between two objects of different colours that each stand on the table
(a box touching the target where no depth jump parts them) or of which one rests on the other's top (a duck on a
box), give a piece that does not reach the plane back to the piece
it stands out in front of and touches (a duck's head in front of its body: a part, not an object), leave
out what runs out of the image upwards (a wall whose top the camera does not see; an object of any size
shows its top), take the target's piece (the one in the region of interest, else the one nearest the image
centre) with what rests on it (a block on a desk; what it rests on stays out, as the table does), give it back its
base (the bottom centimetre, under the height test's threshold: over its
footprint, not facing up), close its holes but those the camera sees the table or the room through (a mug's
handle) and let GrabCut, seeded from it, settle the boundary the depth leaves ragged.
Tolerances grow with each reading's depth, not the image's: a far wall does not loosen them. Depth is in metres
in the camera's optical frame; 0 or NaN means no reading.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from idpose_core.segmentation.confidence import MIN_MASK_CONFIDENCE, mask_confidence
from idpose_core.segmentation.errors import DepthSegmentationError
from idpose_core.segmentation.footprint import faces_up, recover_base
from idpose_core.segmentation.grabcut import grabcut_refine
from idpose_core.segmentation.holes import close_holes
from idpose_core.segmentation.merge import merge_carried_pieces
from idpose_core.segmentation.pieces import connected_pieces, nearest_index
from idpose_core.segmentation.plane import PLANE_TOLERANCE, Plane, backproject, depth_tolerance, support_plane
from idpose_core.segmentation.stacking import with_what_it_carries
from idpose_core.segmentation.target import drop_scenery, nearer_the_centre, target_piece
from idpose_core.segmentation.touching import split_touching
from idpose_core.view_input import ViewInput

MIN_HEIGHT = 0.008  # m, or MIN_HEIGHT_SHARE of the depth when larger: standing on the plane
MIN_HEIGHT_SHARE = 0.015
SUPPORT_HEIGHT = 0.05  # m, or 5 % of the depth when larger: a piece with enough points this close to the plane
# (``stands``) stands on it (a curved bottom starts a few cm up); one without is carried by another piece
FOOT_BAND = 0.01  # m above the height test's threshold: each of two parts kept apart at a crease reaches this low
# (a box's foot, a table's leg; not a marker low on a brick's side, which SUPPORT_HEIGHT would count as standing)


@dataclass(frozen=True)
class DepthCut:
    """``mask`` (H, W) bool of the target; ``depth_mask`` before GrabCut; the support ``plane``; ``note``: what the
    mask left out that touches it or lies at the image centre (the central piece left out as the room, a piece
    touching the object, the object it rests on), else empty;
    ``confidence`` in [0, 1]: how separable the object is from what was left out (``mask_confidence``)."""

    mask: np.ndarray
    depth_mask: np.ndarray
    plane: Plane
    note: str = ""
    confidence: float = 1.0


def depth_cut(view: ViewInput, refine: bool = True, seed: int = 0) -> DepthCut:
    """Cut the target out of ``view`` with its depth (needs ``depth`` and ``intrinsics``; ``gravity_up``
    and ``roi`` help). DepthSegmentationError says why depth cannot do it, for a fallback."""
    if view.depth is None or view.intrinsics is None:
        raise DepthSegmentationError("depth segmentation needs a depth image and the camera intrinsics")
    points, valid = backproject(view.depth, view.intrinsics)
    if valid.mean() < 0.05:
        raise DepthSegmentationError(f"only {100 * valid.mean():.0f} % of the depth image has readings")
    plane = support_plane(points[valid], view.gravity_up, np.random.default_rng(seed))
    height = plane.height(points)
    depth = np.where(valid, view.depth, 0.0)
    threshold = depth_tolerance(depth, MIN_HEIGHT, MIN_HEIGHT_SHARE)
    nearest = nearest_index(valid)
    count, labels = connected_pieces(valid & (height > threshold), depth, valid, nearest)
    known_height = height.ravel()[nearest]  # a hole has its nearest reading's height
    up = faces_up(points, valid, plane)
    count, labels, apart, stacked = split_touching(labels, count, points, known_height, threshold + FOOT_BAND,
                                                   view.rgb, valid, up, plane)
    labels, resting = merge_carried_pieces(labels, count, known_height, points, valid,
                                           depth_tolerance(depth, SUPPORT_HEIGHT, 0.05), plane, view.rgb, up, apart,
                                           stacked)
    on_plane = valid & (np.abs(height) < depth_tolerance(depth, PLANE_TOLERANCE, 0.01))
    kept = drop_scenery(labels, count, known_height, plane)
    piece, support = with_what_it_carries(target_piece(kept, count, view.roi), labels, resting, view.roi)
    notes = []
    if view.roi is None and nearer_the_centre(labels & (kept == 0), piece):
        notes.append("the piece nearest the image centre runs out of the image upwards and was left out as the room "
                     "(an object cut off at the image's top?)")
    if support.any():
        notes.append("the object rests on another object of another colour, which was left out as the table is")
    piece = close_holes(recover_base(piece, points, valid, height, plane, threshold, up), points, valid, height, plane,
                        threshold)
    mask = grabcut_refine(view.rgb, piece, on_plane, ~valid) if refine else piece
    confidence = mask_confidence(piece, points, valid, valid & (height > threshold) & ~support)
    if confidence < MIN_MASK_CONFIDENCE:
        notes.append(f"something touching the object was left out ({100 * (1 - confidence):.0f} % of the readings "
                     "along its outline are attached to it)")
    return DepthCut(mask=mask, depth_mask=piece, plane=plane, note="; ".join(notes), confidence=confidence)
