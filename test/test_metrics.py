"""The paper's metrics, and the reproduction of the official ID-Pose figures from its released outputs."""
import json
import math
from pathlib import Path

import numpy as np
import pytest

from idpose_core.cameras import relative_spherical, spherical_to_c2w
from idpose_core.metrics import aggregate, pair_errors, rotation_angle_deg

REFERENCE = Path(__file__).resolve().parents[2] / "shared" / "reference" / "idpose-official"


def official_pairs():
    """(anchor c2w, target c2w, predicted rel_sph, gt_rel_sph, views in the set) of the 9 omni3d pairs."""
    outputs = sorted(REFERENCE.glob("outputs/omni3d/*/pose.json"))
    if not outputs:
        pytest.skip(f"official reference outputs not found under {REFERENCE}")
    pairs = []
    for output in outputs:
        result = json.loads(output.read_text())
        poses = REFERENCE / "data" / "omni3d" / output.parent.name.rsplit("_", 1)[0] / "poses"
        anchor = np.load(poses / f"{result['anchor_vid']}.npy")
        targets = {vid: obs for vid, obs in result["obs"].items() if vid != result["anchor_vid"]}
        for vid, obs in targets.items():
            pairs.append((anchor, np.load(poses / f"{vid}.npy"), obs["rel_sph"], obs["gt_rel_sph"], len(targets) + 1))
    return pairs


def test_relative_spherical_reproduces_official_ground_truth():
    pairs = official_pairs()
    assert len(pairs) == 9
    for anchor, target, _, gt_rel_sph, _ in pairs:
        np.testing.assert_allclose(relative_spherical(anchor, target), gt_rel_sph, atol=1e-6)


def test_official_figures_are_reproduced():
    """The official script prints 13.2672 deg, 88.89 % (both), 0.21028, 88.89 % over 9 pairs.

    The official run is float32; in float64 the mean rotation error is 13.26729, so it is held to one
    unit of the last printed digit (1e-4 deg) rather than half of one.
    """
    records = []
    for anchor, target, rel_sph, _, n in official_pairs():
        rot_err, pos_err = pair_errors(np.array(rel_sph), anchor, target)
        records.append({"n": n, "rot_err_deg": rot_err, "pos_err": pos_err})
    report = aggregate(records)
    assert set(report) == {"4", "all"}
    assert report["4"] == report["all"]
    summary = report["all"]
    assert summary["pairs"] == 9
    assert abs(summary["mean_rot_err_deg"] - 13.2672) < 1e-4
    assert round(100 * summary["rot_acc_15"], 2) == 88.89
    assert round(100 * summary["rot_acc_30"], 2) == 88.89
    assert abs(summary["mean_pos_err"] - 0.21028) <= 5e-6
    assert round(100 * summary["pos_acc_0.2"], 2) == 88.89
    json.dumps(report)


def test_exact_prediction_has_zero_error():
    anchor = spherical_to_c2w(np.array([1.1, 0.4, 3.0]))
    target = spherical_to_c2w(np.array([0.8, 2.9, 3.0]))
    rot_err, pos_err = pair_errors(relative_spherical(anchor, target), anchor, target)
    assert rot_err < 1e-5 and pos_err < 1e-9


def test_azimuth_error_on_the_equator():
    """On the equator a pure azimuth error of a is a rotation of a about the vertical and a chord 2 sin(a/2)."""
    anchor = spherical_to_c2w(np.array([math.pi / 2, 0.0, 2.0]))
    target = spherical_to_c2w(np.array([math.pi / 2, 1.0, 2.0]))
    rot_err, pos_err = pair_errors(np.array([0.0, 1.0 + math.radians(20.0), 0.0]), anchor, target)
    np.testing.assert_allclose(rot_err, 20.0, atol=1e-9)
    np.testing.assert_allclose(pos_err, 2 * math.sin(math.radians(10.0)), atol=1e-12)


def test_relative_radius_is_rescaled_by_anchor_distance_over_1_85():
    """A predicted radius offset of 0.37 units (0.2 of 1.85) is 0.2 anchor distances: rotation unaffected."""
    anchor = spherical_to_c2w(np.array([1.0, 0.0, 5.0]))
    rot_err, pos_err = pair_errors(np.array([0.0, 0.0, 0.37]), anchor, anchor)
    np.testing.assert_allclose([rot_err, pos_err], [0.0, 0.2], atol=1e-7)


def test_pair_errors_are_batched():
    anchors = spherical_to_c2w(np.array([[1.0, 0.0, 2.0], [1.4, 3.0, 4.0]]))
    rot_err, pos_err = pair_errors(np.array([[0.1, 0.2, 0.0], [0.0, 0.0, 0.0]]), anchors, anchors)
    assert rot_err.shape == pos_err.shape == (2,)
    assert rot_err[0] > 1.0 and rot_err[1] < 1e-5


def test_rotation_angle_of_a_known_rotation():
    c, s = math.cos(0.5), math.sin(0.5)
    about_x = np.array([[1, 0, 0], [0, c, -s], [0, s, c]])
    np.testing.assert_allclose(rotation_angle_deg(about_x, np.eye(3)), math.degrees(0.5))
    np.testing.assert_allclose(rotation_angle_deg(np.eye(3), np.eye(3)), 0.0)


def test_aggregate_groups_by_view_count():
    records = [
        {"n": 2, "rot_err_deg": 10.0, "pos_err": 0.1},
        {"n": 2, "rot_err_deg": 20.0, "pos_err": 0.3},
        {"n": 3, "rot_err_deg": 40.0, "pos_err": 0.1, "sample": "extra keys are ignored"},
        {"n": 3, "rot_err_deg": 14.9, "pos_err": 0.19},
    ]
    report = aggregate(records)
    assert list(report) == ["2", "3", "all"]
    assert report["2"] == {
        "pairs": 2, "distinct_pairs": 2, "rot_acc_15": 0.5, "rot_acc_30": 1.0, "pos_acc_0.2": 0.5,
        "mean_rot_err_deg": 15.0, "median_rot_err_deg": 15.0, "mean_pos_err": 0.2, "median_pos_err": 0.2,
    }
    assert report["3"]["rot_acc_30"] == 0.5 and report["3"]["pos_acc_0.2"] == 1.0
    assert report["all"]["pairs"] == 4 and report["all"]["rot_acc_15"] == 0.5
    assert report["all"]["mean_rot_err_deg"] == pytest.approx(84.9 / 4)
    assert json.loads(json.dumps(report)) == report


def test_distinct_pairs_count_a_repeated_pair_once_and_the_pairs_of_two_objects_apart():
    pair = {"n": 2, "anchor_view": 0, "view": 1, "rot_err_deg": 5.0, "pos_err": 0.1}
    report = aggregate([pair, dict(pair), {**pair, "view": 2}, {**pair, "n": 4}])
    assert (report["2"]["pairs"], report["2"]["distinct_pairs"]) == (3, 2)
    assert (report["all"]["pairs"], report["all"]["distinct_pairs"]) == (4, 3)
    for key in ("bag", "input", "dataset"):
        assert aggregate([{**pair, key: "a"}, {**pair, key: "b"}])["all"]["distinct_pairs"] == 2


def test_accuracy_thresholds_are_strict():
    report = aggregate([{"n": 2, "rot_err_deg": 15.0, "pos_err": 0.2}])
    assert report["all"]["rot_acc_15"] == 0.0 and report["all"]["pos_acc_0.2"] == 0.0


@pytest.mark.parametrize(
    "records, message",
    [
        ([], "no metric records"),
        ([{"n": 2, "rot_err_deg": 1.0}], "record 0 lacks pos_err"),
        ([{"n": 2, "rot_err_deg": float("nan"), "pos_err": 0.1}], "record 0 has a non-finite"),
    ],
)
def test_aggregate_rejects_bad_records(records, message):
    with pytest.raises(ValueError, match=message):
        aggregate(records)
