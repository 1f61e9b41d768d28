"""Rigid transforms over time, as a TF tree: chained lookups, lerp/slerp interpolation (numpy only).

A transform ``T_parent_child`` (4, 4) maps points in the child frame to the parent frame, i.e. it
is the pose of the child in the parent, as in a ``geometry_msgs/TransformStamped``. Quaternions are
``(x, y, z, w)`` as in ROS messages. Stamps are integer nanoseconds.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


class TransformLookupError(LookupError):
    """A transform between two frames at a stamp is not available (unknown frame, no link, out of range)."""


def quaternion_to_matrix(quaternion: np.ndarray) -> np.ndarray:
    """Unit quaternion(s) ``(..., 4)`` as (x, y, z, w) -> rotation matrices ``(..., 3, 3)``; normalises first."""
    q = np.asarray(quaternion, dtype=np.float64)
    norm = np.linalg.norm(q, axis=-1, keepdims=True)
    if np.any(norm < 1e-12):
        raise ValueError("quaternion of zero length has no rotation")
    x, y, z, w = np.moveaxis(q / norm, -1, 0)
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
            np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
            np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1),
        ],
        -2,
    )


def _matrix_to_quaternion_single(r: np.ndarray) -> np.ndarray:
    """One rotation (3, 3) -> (x, y, z, w) by the numerically safest diagonal (Shepperd), canonically signed."""
    trace = np.trace(r)
    if trace > max(r[0, 0], r[1, 1], r[2, 2]):
        s = 2.0 * np.sqrt(1.0 + trace)
        q = [(r[2, 1] - r[1, 2]) / s, (r[0, 2] - r[2, 0]) / s, (r[1, 0] - r[0, 1]) / s, s / 4]
    elif r[0, 0] >= r[1, 1] and r[0, 0] >= r[2, 2]:
        s = 2.0 * np.sqrt(1.0 + r[0, 0] - r[1, 1] - r[2, 2])
        q = [s / 4, (r[0, 1] + r[1, 0]) / s, (r[0, 2] + r[2, 0]) / s, (r[2, 1] - r[1, 2]) / s]
    elif r[1, 1] >= r[2, 2]:
        s = 2.0 * np.sqrt(1.0 + r[1, 1] - r[0, 0] - r[2, 2])
        q = [(r[0, 1] + r[1, 0]) / s, s / 4, (r[1, 2] + r[2, 1]) / s, (r[0, 2] - r[2, 0]) / s]
    else:
        s = 2.0 * np.sqrt(1.0 + r[2, 2] - r[0, 0] - r[1, 1])
        q = [(r[0, 2] + r[2, 0]) / s, (r[1, 2] + r[2, 1]) / s, s / 4, (r[1, 0] - r[0, 1]) / s]
    return canonical_sign(np.asarray(q))


def canonical_sign(q: np.ndarray) -> np.ndarray:
    """The one of q, -q (both the same rotation) with w > 0, or, when w == 0, whose first non-zero of x, y, z
    is positive: the convention ``msg_adapters.quaternions`` follows too, so both layers write the same numbers."""
    leading = next((value for value in q[[3, 0, 1, 2]] if value != 0.0), 1.0)
    return q if leading > 0 else -q


def matrix_to_quaternion(rotation: np.ndarray) -> np.ndarray:
    """Rotation matrices ``(..., 3, 3)`` -> unit quaternions ``(..., 4)`` as (x, y, z, w), signed by
    ``canonical_sign``."""
    r = np.asarray(rotation, dtype=np.float64)
    flat = r.reshape(-1, 3, 3)
    quats = np.stack([_matrix_to_quaternion_single(m) for m in flat]) if len(flat) else np.zeros((0, 4))
    return quats.reshape(r.shape[:-2] + (4,))


def rigid_transform(translation: np.ndarray, quaternion: np.ndarray) -> np.ndarray:
    """Translation ``(..., 3)`` and quaternion ``(..., 4)`` (x, y, z, w) -> homogeneous ``(..., 4, 4)``."""
    t = np.asarray(translation, dtype=np.float64)
    rotation = quaternion_to_matrix(quaternion)
    out = np.zeros(rotation.shape[:-2] + (4, 4))
    out[..., :3, :3] = rotation
    out[..., :3, 3] = t
    out[..., 3, 3] = 1.0
    return out


def split_transform(transform: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Homogeneous ``(..., 4, 4)`` -> (translation ``(..., 3)``, quaternion ``(..., 4)`` x, y, z, w)."""
    transform = np.asarray(transform, dtype=np.float64)
    return transform[..., :3, 3].copy(), matrix_to_quaternion(transform[..., :3, :3])


def invert_transform(transform: np.ndarray) -> np.ndarray:
    """Inverse of rigid transforms ``(..., 4, 4)`` (transpose the rotation, rotate back the translation)."""
    transform = np.asarray(transform, dtype=np.float64)
    rotation_t = np.swapaxes(transform[..., :3, :3], -1, -2)
    out = np.zeros_like(transform)
    out[..., :3, :3] = rotation_t
    out[..., :3, 3] = -np.einsum("...ij,...j->...i", rotation_t, transform[..., :3, 3])
    out[..., 3, 3] = 1.0
    return out


def slerp(q0: np.ndarray, q1: np.ndarray, weight: float) -> np.ndarray:
    """Spherical linear interpolation of unit quaternions (4,) along the shorter arc; weight 0 -> q0, 1 -> q1."""
    q0 = np.asarray(q0, dtype=np.float64) / np.linalg.norm(q0)
    q1 = np.asarray(q1, dtype=np.float64) / np.linalg.norm(q1)
    dot = float(np.dot(q0, q1))
    if dot < 0.0:
        q1, dot = -q1, -dot
    if dot > 1.0 - 1e-10:
        q = q0 + weight * (q1 - q0)
        return q / np.linalg.norm(q)
    angle = np.arccos(dot)
    return (np.sin((1.0 - weight) * angle) * q0 + np.sin(weight * angle) * q1) / np.sin(angle)


def interpolate_transform(
    stamp0: int, translation0: np.ndarray, quaternion0: np.ndarray,
    stamp1: int, translation1: np.ndarray, quaternion1: np.ndarray, stamp: int,
) -> np.ndarray:
    """Transform (4, 4) at ``stamp`` between two samples: lerp of the translation, slerp of the rotation."""
    weight = 0.0 if stamp1 == stamp0 else (stamp - stamp0) / (stamp1 - stamp0)
    translation = (1.0 - weight) * np.asarray(translation0) + weight * np.asarray(translation1)
    return rigid_transform(translation, slerp(quaternion0, quaternion1, weight))


@dataclass
class _Link:
    """The samples of one parent -> child edge of the tree, kept sorted by stamp."""

    parent: str
    static: bool
    stamps: list[int] = field(default_factory=list)
    translations: list[np.ndarray] = field(default_factory=list)
    quaternions: list[np.ndarray] = field(default_factory=list)
    _sorted: bool = True

    def add(self, stamp: int, translation: np.ndarray, quaternion: np.ndarray) -> None:
        if self.static:  # a static transform holds at every time; the latest one wins, as in tf2
            self.stamps, self.translations, self.quaternions = [], [], []
        elif self.stamps and stamp < self.stamps[-1]:
            self._sorted = False
        self.stamps.append(int(stamp))
        self.translations.append(np.asarray(translation, dtype=np.float64))
        self.quaternions.append(np.asarray(quaternion, dtype=np.float64))

    def _sort(self) -> None:
        order = np.argsort(self.stamps, kind="stable")
        self.stamps = [self.stamps[i] for i in order]
        self.translations = [self.translations[i] for i in order]
        self.quaternions = [self.quaternions[i] for i in order]
        self._sorted = True

    def at(self, stamp: int, child: str) -> np.ndarray:
        """``T_parent_child`` (4, 4) at ``stamp``: exact sample, or interpolated between its neighbours."""
        if self.static:
            return rigid_transform(self.translations[0], self.quaternions[0])
        if not self._sorted:
            self._sort()
        index = int(np.searchsorted(self.stamps, stamp, side="left"))
        if index < len(self.stamps) and self.stamps[index] == stamp:
            return rigid_transform(self.translations[index], self.quaternions[index])
        if index == 0 or index == len(self.stamps):
            raise TransformLookupError(
                f"no transform {self.parent} -> {child} at {stamp * 1e-9:.9f} s: it is known only from "
                f"{self.stamps[0] * 1e-9:.9f} s to {self.stamps[-1] * 1e-9:.9f} s (no extrapolation)"
            )
        lo, hi = index - 1, index
        return interpolate_transform(
            self.stamps[lo], self.translations[lo], self.quaternions[lo],
            self.stamps[hi], self.translations[hi], self.quaternions[hi], stamp,
        )


class TransformBuffer:
    """A TF tree over time: add parent -> child samples, look up any frame in any other at a stamp."""

    def __init__(self) -> None:
        self._links: dict[str, _Link] = {}

    @property
    def frames(self) -> set[str]:
        """Every frame named so far, parents and children."""
        return set(self._links) | {link.parent for link in self._links.values()}

    def add(self, parent: str, child: str, stamp: int, translation: np.ndarray, quaternion: np.ndarray,
            static: bool = False) -> None:
        """Record ``T_parent_child`` at ``stamp`` (ns); a frame has one parent, as in a TF tree."""
        parent, child = parent.lstrip("/"), child.lstrip("/")
        if parent == child:
            raise ValueError(f"transform from frame {parent!r} to itself")
        link = self._links.get(child)
        if link is None:
            link = self._links[child] = _Link(parent=parent, static=static)
        elif link.parent != parent:
            raise ValueError(f"frame {child!r} has two parents: {link.parent!r} and {parent!r}")
        elif link.static != static:
            raise ValueError(f"transform {parent} -> {child} is published both on /tf and /tf_static")
        link.add(stamp, translation, quaternion)

    def _chain_to_root(self, frame: str) -> list[str]:
        chain = [frame]
        while chain[-1] in self._links:
            chain.append(self._links[chain[-1]].parent)
            if len(chain) > len(self._links) + 1:
                raise TransformLookupError(f"the transform tree has a loop through {frame!r}")
        return chain

    def _root_from(self, chain: list[str], stamp: int) -> np.ndarray:
        """``T_last_first`` along ``chain`` (child first): the pose of chain[0] in chain[-1]."""
        transform = np.eye(4)
        for child in chain[:-1]:
            transform = self._links[child].at(stamp, child) @ transform
        return transform

    def lookup(self, target: str, source: str, stamp: int) -> np.ndarray:
        """``T_target_source`` (4, 4) at ``stamp`` (ns): the pose of frame ``source`` in frame ``target``."""
        target, source = target.lstrip("/"), source.lstrip("/")
        for frame in (target, source):
            if frame not in self.frames:
                known = ", ".join(sorted(self.frames)) or "none"
                raise TransformLookupError(f"frame {frame!r} is not in the transform tree (frames: {known})")
        source_chain, target_chain = self._chain_to_root(source), self._chain_to_root(target)
        common = next((f for f in source_chain if f in target_chain), None)
        if common is None:
            raise TransformLookupError(f"frames {target!r} and {source!r} are not connected in the transform tree")
        common_from_source = self._root_from(source_chain[: source_chain.index(common) + 1], stamp)
        common_from_target = self._root_from(target_chain[: target_chain.index(common) + 1], stamp)
        return invert_transform(common_from_target) @ common_from_source
