"""The paper's pose metrics, computed as the official ID-Pose evaluation does.

Per (anchor, target) pair the predicted relative pose is applied to the anchor's true spherical
coordinates (relative radius rescaled by ``anchor_radius / 1.85``); the predicted camera looks at the
origin with up +z. Rotation error is the angle between the true and the predicted camera rotations;
position error is the distance between the camera centres divided by the anchor's distance.
"""
from __future__ import annotations

from collections import defaultdict
from collections.abc import Iterable, Mapping

import numpy as np

from idpose_core.cameras import ZERO123_RADIUS, apply_relative, c2w_to_spherical, spherical_to_c2w
from idpose_core.spherical import relative

ROT_THRESHOLDS_DEG = (15.0, 30.0)
POS_THRESHOLD = 0.2
OBJECT_KEYS = ("dataset", "input", "bag")  # what tells apart the pooled records of different objects


def rotation_angle_deg(rot_a: np.ndarray, rot_b: np.ndarray) -> np.ndarray:
    """Angle (...,) in degrees of the rotation taking ``rot_b`` (..., 3, 3) to ``rot_a`` (..., 3, 3)."""
    relative = rot_a @ np.swapaxes(rot_b, -1, -2)
    cosine = (np.trace(relative, axis1=-2, axis2=-1) - 1.0) / 2.0
    return np.degrees(np.arccos(np.clip(cosine, -1.0, 1.0)))


def pair_errors(
    pred_rel_sph: np.ndarray, anchor_c2w: np.ndarray, target_c2w: np.ndarray, radius_scale: float = ZERO123_RADIUS
) -> tuple[np.ndarray, np.ndarray]:
    """(rotation error in degrees, normalised camera-centre error), each (...,), of predicted relative poses.

    ``pred_rel_sph`` (..., 3) anchor -> target in Zero-1-to-3 units; ``anchor_c2w``, ``target_c2w``
    (..., 4, 4) true camera-to-world matrices with OpenGL camera axes (as the reference poses are).
    """
    anchor_sph = c2w_to_spherical(np.asarray(anchor_c2w, dtype=np.float64))
    pred_c2w = spherical_to_c2w(apply_relative(anchor_sph, pred_rel_sph, radius_scale))
    return camera_errors(pred_c2w, target_c2w, anchor_sph[..., 2])


def camera_errors(pred_c2w: np.ndarray, true_c2w: np.ndarray, anchor_distance: np.ndarray | float
                  ) -> tuple[np.ndarray, np.ndarray]:
    """(rotation error in degrees, camera-centre error / ``anchor_distance``), each (...,), of estimated cameras
    against true ones, both camera-to-world (..., 4, 4) with the same camera axes."""
    pred_c2w, true_c2w = np.asarray(pred_c2w, dtype=np.float64), np.asarray(true_c2w, dtype=np.float64)
    rot_err = rotation_angle_deg(true_c2w[..., :3, :3], pred_c2w[..., :3, :3])
    pos_err = np.linalg.norm(pred_c2w[..., :3, 3] - true_c2w[..., :3, 3], axis=-1) / anchor_distance
    return rot_err, pos_err


def random_pose_errors(anchor_c2w: np.ndarray, target_c2w: np.ndarray, draws: int, rng: np.random.Generator
                       ) -> tuple[np.ndarray, np.ndarray]:
    """The random-pose baseline: (rotation errors, position errors), each (P, draws), of guessing each of P
    pairs' target camera uniformly on the sphere around the object at the anchor's distance.

    ``anchor_c2w``, ``target_c2w`` (P, 4, 4) true OpenGL camera-to-world matrices; scored by ``pair_errors``.
    """
    anchor_c2w = np.asarray(anchor_c2w, dtype=np.float64)[:, None]
    guess = random_relative_poses(c2w_to_spherical(anchor_c2w), (len(anchor_c2w), draws), rng)
    return pair_errors(guess, anchor_c2w, np.asarray(target_c2w, dtype=np.float64)[:, None])


def random_relative_poses(anchor_sph: np.ndarray, shape: tuple[int, ...], rng: np.random.Generator) -> np.ndarray:
    """Relative poses ``shape + (3,)`` from anchors ``anchor_sph`` (broadcast to ``shape + (3,)``) to cameras drawn
    uniformly on the sphere at the anchor's distance (so the relative radius is 0 in any unit)."""
    anchor_sph = np.broadcast_to(np.asarray(anchor_sph, dtype=np.float64), shape + (3,))
    guess = np.stack([np.arccos(rng.uniform(-1.0, 1.0, shape)), rng.uniform(0.0, 2 * np.pi, shape),
                      anchor_sph[..., 2]], axis=-1)
    return relative(anchor_sph, guess)


def _summary(rot_err: np.ndarray, pos_err: np.ndarray, distinct_pairs: int) -> dict[str, float | int]:
    summary: dict[str, float | int] = {"pairs": int(rot_err.size), "distinct_pairs": distinct_pairs}
    for threshold in ROT_THRESHOLDS_DEG:
        summary[f"rot_acc_{threshold:g}"] = float(np.mean(rot_err < threshold))
    summary[f"pos_acc_{POS_THRESHOLD:g}"] = float(np.mean(pos_err < POS_THRESHOLD))
    summary["mean_rot_err_deg"] = float(np.mean(rot_err))
    summary["median_rot_err_deg"] = float(np.median(rot_err))
    summary["mean_pos_err"] = float(np.mean(pos_err))
    summary["median_pos_err"] = float(np.median(pos_err))
    return summary


def aggregate(records: Iterable[Mapping]) -> dict[str, dict[str, float | int]]:
    """Accuracies (fractions in [0, 1]), mean and median errors and pair counts, per view count n and overall.

    ``records`` are per-pair mappings with at least ``n`` (views in the set), ``rot_err_deg`` and
    ``pos_err``. Returns a JSON-ready dict keyed by ``str(n)`` in increasing order, then ``"all"``; each
    group has ``pairs``, ``distinct_pairs`` (``pair_identity``: a pair scored twice counts once),
    ``rot_acc_15``, ``rot_acc_30``, ``pos_acc_0.2``, ``mean_rot_err_deg``, ``median_rot_err_deg``,
    ``mean_pos_err`` and ``median_pos_err``.
    """
    groups: dict[int, list[tuple[float, float]]] = defaultdict(list)
    identities: dict[int, set[tuple]] = defaultdict(set)
    for index, record in enumerate(records):
        missing = [key for key in ("n", "rot_err_deg", "pos_err") if key not in record]
        if missing:
            raise ValueError(f"metric record {index} lacks {', '.join(missing)}")
        rot_err, pos_err = float(record["rot_err_deg"]), float(record["pos_err"])
        if not (np.isfinite(rot_err) and np.isfinite(pos_err)):
            raise ValueError(f"metric record {index} has a non-finite error ({rot_err}, {pos_err})")
        groups[int(record["n"])].append((rot_err, pos_err))
        identities[int(record["n"])].add(pair_identity(record, index))
    if not groups:
        raise ValueError("no metric records to aggregate")
    result = {str(n): _summary(*np.array(groups[n]).T, len(identities[n])) for n in sorted(groups)}
    every = np.array([pair for n in sorted(groups) for pair in groups[n]])
    result["all"] = _summary(*every.T, sum(len(pairs) for pairs in identities.values()))
    return result


def pair_identity(record: Mapping, index: int) -> tuple:
    """What makes a scored pair different from another: its object (``dataset``, ``input`` or ``bag``, where the
    records of several are pooled), its view count and its two view ids; a record without view ids (``anchor_view``,
    ``view``) is its own pair (``index``: its place in the records)."""
    if "anchor_view" not in record or "view" not in record:
        return ("record", index)
    return (*(record.get(key) for key in OBJECT_KEYS), int(record["n"]), record["anchor_view"], record["view"])
