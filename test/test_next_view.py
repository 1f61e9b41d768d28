"""Where to look next: the reachable grid, and the suggested camera on layouts whose answer is known by geometry."""
from __future__ import annotations

import math

import numpy as np
import pytest

from idpose_core.cameras import first_camera_frame_poses
from idpose_core.depth_fusion.clouds import ObjectCloud
from idpose_core.depth_fusion.refinement import DepthRefinement, ViewRefinement
from idpose_core.gravity import rz, with_roll
from idpose_core.next_view import ReachableSet, pose_spheres, suggest_next_view, view_spheres
from idpose_core.next_view.suggestion import angles_between
from idpose_core.pipeline import PipelineSettings, next_view_for
from idpose_core.solver import SolverConfig
from idpose_core.solver.result import SolverResult

DISTANCE = 0.6
POLAR = math.radians(60.0)


def two_views(answer_az_deg: float, rival_az_deg: float | None) -> tuple[np.ndarray, ...]:
    """The anchor (polar 60, azimuth 0) and one view at ``answer_az_deg`` whose runner-up is at ``rival_az_deg``
    (None: unambiguous): spheres, rivals, ambiguous, confidence."""
    spheres = view_spheres(np.array([[0.0, math.radians(answer_az_deg), 0.0]]), POLAR, DISTANCE)
    rival = np.full((1, 3), np.nan) if rival_az_deg is None else np.array([[0.0, math.radians(rival_az_deg), 0.0]])
    rivals = view_spheres(rival, POLAR, DISTANCE)
    rivals[0] = np.nan
    return spheres, rivals, np.array([False, rival_az_deg is not None]), np.array([1.0, 0.1])


def degrees(sphere: np.ndarray) -> tuple[float, float]:
    """(polar, azimuth) of a sphere in degrees, the azimuth in (-180, 180]."""
    azimuth = (math.degrees(sphere[1]) + 180.0) % 360.0 - 180.0
    return math.degrees(sphere[0]), 180.0 if azimuth == -180.0 else azimuth


def test_the_reachable_grid_spans_its_ranges_once():
    reachable = ReachableSet(polar_deg=(40.0, 80.0), azimuth_deg=(-180.0, 180.0), distance=(0.2, 1.0), step_deg=20.0)
    candidates = reachable.candidates(5.0)
    polar, azimuth = np.degrees(candidates[:, 0]), np.degrees(candidates[:, 1])
    assert sorted(set(np.round(polar, 6))) == [40.0, 60.0, 80.0]
    assert len(set(np.round(azimuth, 6))) == 18, "a full turn does not repeat -180 as 180"
    assert np.allclose(candidates[:, 2], 1.0), "the distance is clipped into the reachable range"
    assert np.allclose(ReachableSet(distance=(0.2, 1.0)).candidates(0.5)[:, 2], 0.5)


@pytest.mark.parametrize("kwargs, words", [
    ({"polar_deg": (100.0, 30.0)}, "polar_deg"),
    ({"polar_deg": (-10.0, 30.0)}, "polar_deg"),
    ({"azimuth_deg": (-270.0, 180.0)}, "more than a turn"),
    ({"distance": (0.0, 1.0)}, "distance"),
    ({"step_deg": 0.0}, "step_deg"),
])
def test_a_bad_reachable_set_is_refused_by_name(kwargs, words):
    with pytest.raises(ValueError, match=words):
        ReachableSet(**kwargs)


def test_view_spheres_place_the_views_and_keep_missing_rows():
    spheres = view_spheres(np.array([[0.1, math.pi / 2, 0.0], [np.nan, np.nan, np.nan]]), POLAR, DISTANCE)
    assert np.allclose(spheres[0], [POLAR, 0.0, DISTANCE])
    assert np.allclose(spheres[1], [POLAR + 0.1, math.pi / 2, DISTANCE])
    assert np.isnan(spheres[2]).all()


def test_pose_spheres_undo_placing_rolled_cameras_and_keep_missing_rows():
    spheres = np.array([[POLAR, 0.0, DISTANCE], [math.radians(80.0), math.radians(130.0), 0.9],
                        [math.radians(35.0), math.radians(-40.0), 0.4]])
    rolls = np.radians([20.0, -35.0, 5.0])
    poses = with_roll(first_camera_frame_poses(spheres), rolls)
    poses[2] = np.nan
    found = pose_spheres(poses, POLAR, DISTANCE, float(rolls[0]))
    assert np.allclose(found[:2], spheres[:2] % [np.inf, 2 * math.pi, np.inf])
    assert np.isnan(found[2]).all()


def test_bridge_stands_between_the_trusted_anchor_and_the_answer():
    """Answer at azimuth 60, runner-up at 240: on the bisector of the anchor and the answer both links are equal
    and the runner-up is far, so that camera tells the two apart."""
    spheres, rivals, ambiguous, confidence = two_views(60.0, 240.0)
    suggestion = suggest_next_view(spheres, rivals, ambiguous, confidence, ReachableSet())
    assert degrees(suggestion.sphere)[1] == pytest.approx(30.0)
    to_anchor, to_answer = np.degrees(angles_between(suggestion.sphere[None], spheres))[0]
    to_rival = math.degrees(angles_between(suggestion.sphere[None], rivals[1:])[0, 0])
    assert to_anchor == pytest.approx(to_answer) and to_rival - to_answer > 90.0


def test_contrast_stands_on_the_nearer_hypothesis():
    suggestion = suggest_next_view(*two_views(60.0, 240.0), ReachableSet(), criterion="contrast")
    assert degrees(suggestion.sphere) == pytest.approx((60.0, 60.0))
    assert suggestion.view == 1 and "ambiguous view 1" in suggestion.reason and 0.0 < suggestion.gain <= 1.0


def test_without_ambiguity_the_farthest_reachable_camera_widens_coverage():
    """Views at azimuths 0 and 60 (polar 60): the direction farthest from both is polar 120, azimuth -150; the arm
    reaches polar 100 at most."""
    suggestion = suggest_next_view(*two_views(60.0, None), ReachableSet())
    assert degrees(suggestion.sphere) == pytest.approx((100.0, -150.0))
    assert suggestion.view is None and suggestion.reason.startswith("coverage")


def test_the_suggestion_stays_in_the_reachable_set():
    reachable = ReachableSet(polar_deg=(80.0, 90.0), azimuth_deg=(90.0, 180.0))
    for rival in (240.0, None):
        polar, azimuth = degrees(suggest_next_view(*two_views(60.0, rival), reachable).sphere)
        assert 80.0 <= polar <= 90.0 and 90.0 <= azimuth <= 180.0


def test_the_pose_looks_at_the_object_from_the_sphere_upright():
    suggestion = suggest_next_view(*two_views(60.0, 240.0), ReachableSet())
    pose = suggestion.pose
    centre = np.array([0.0, 0.0, DISTANCE])  # the object, straight ahead of the anchor camera
    assert np.allclose(pose[:3, :3].T @ pose[:3, :3], np.eye(3)) and np.linalg.det(pose[:3, :3]) > 0
    assert np.linalg.norm(centre - pose[:3, 3]) == pytest.approx(DISTANCE)
    assert np.allclose(pose[:3, 3] + DISTANCE * pose[:3, 2], centre), "its optical axis goes through the object"
    up = np.array([0.0, -math.sin(POLAR), -math.cos(POLAR)])  # world up in the level-rolled anchor's optical frame
    assert abs(pose[:3, 0] @ up) < 1e-9, "its x axis is level: no roll about gravity"
    assert pose[:3, 1] @ up < 0.0, "its image is the right way up"
    polar, azimuth = suggestion.sphere[:2]
    anchor_direction = np.array([math.sin(POLAR), 0.0, math.cos(POLAR)])
    direction = np.array([math.sin(polar) * math.cos(azimuth), math.sin(polar) * math.sin(azimuth), math.cos(polar)])
    angle = math.acos(np.clip(anchor_direction @ direction, -1.0, 1.0))
    assert pose[2, 2] == pytest.approx(math.cos(angle)), "its axis turned from the anchor's as the spheres are apart"


def test_bad_arguments_name_the_problem():
    spheres, rivals, ambiguous, confidence = two_views(60.0, 240.0)
    with pytest.raises(ValueError, match="criterion"):
        suggest_next_view(spheres, rivals, ambiguous, confidence, ReachableSet(), criterion="closest")
    with pytest.raises(ValueError, match="same N views"):
        suggest_next_view(spheres, rivals[:1], ambiguous, confidence, ReachableSet())


def test_a_rolled_anchor_gets_the_same_camera_in_its_own_frame():
    """The anchor camera rolled by 0.4 rad about its axis: the suggested camera is the same place, still level."""
    layout = two_views(60.0, 240.0)
    upright = suggest_next_view(*layout, ReachableSet()).pose
    rolled = suggest_next_view(*layout, ReachableSet(), anchor_roll=0.4).pose
    turn = rz(0.4)
    up = turn.T @ np.array([0.0, -math.sin(POLAR), -math.cos(POLAR)])  # world up in the rolled anchor's frame
    assert np.allclose(rolled[:3, 3], turn.T @ upright[:3, 3])
    assert abs(rolled[:3, 0] @ up) < 1e-9 and rolled[:3, 1] @ up < 0.0


def test_where_the_verifier_chose_a_pose_its_ambiguity_sets_the_next_view():
    """The solver is sure of view 1 at azimuth 90; the verifier placed it at 60 with a runner-up at 150, too close
    to tell: the next camera settles the verifier's doubt, not the solver's."""
    solved = SolverResult(np.array([[0.0, math.radians(90.0), 0.0]]), np.zeros(1), np.full((1, 3), np.nan),
                          np.full(1, np.nan), np.array([False]), np.ones(1), 0, 0)
    settings = PipelineSettings(SolverConfig())
    assert next_view_for(solved, math.degrees(POLAR), DISTANCE, 0.0, settings).view is None
    spheres = np.array([[POLAR, 0.0, DISTANCE], [POLAR, math.radians(60.0), DISTANCE],
                        [POLAR, math.radians(150.0), DISTANCE]])
    placed = first_camera_frame_poses(spheres)
    refinements = [ViewRefinement(False, "the anchor", math.nan, math.nan, 0.0, 0.0),
                   ViewRefinement(True, "", 1.0, 0.0, 30.0, 0.1, "gravity", 0.1, True)]
    cloud = ObjectCloud(np.zeros((1, 3)), np.zeros((1, 3), np.uint8))
    depth = DepthRefinement(placed[:2], refinements, cloud, 0.005, np.stack([np.full((4, 4), np.nan), placed[2]]))
    suggestion = next_view_for(solved, math.degrees(POLAR), DISTANCE, 0.0, settings, depth)
    assert suggestion.view == 1
    assert "76 deg apart" in suggestion.reason  # polar 60, azimuths 90 deg apart
