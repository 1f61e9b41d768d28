"""Rigid transforms over time, as a TF tree: chained lookups, lerp/slerp interpolation (numpy, scipy's rotations).

A transform ``T_parent_child`` (4, 4) maps points in the child frame to the parent frame, i.e. it
is the pose of the child in the parent, as in a ``geometry_msgs/TransformStamped``. Quaternions are
``(x, y, z, w)`` as in ROS messages. Stamps are integer nanoseconds.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial.transform import Rotation, Slerp


class TransformLookupError(LookupError):
    """A transform between two frames at a stamp is not available (unknown frame, no link, out of range)."""


def rigid_transform(translation: np.ndarray, quaternion: np.ndarray) -> np.ndarray:
    """Translation ``(..., 3)`` and quaternion ``(..., 4)`` (x, y, z, w, any non-zero norm) -> homogeneous
    ``(..., 4, 4)``; ValueError for a zero quaternion."""
    q = np.asarray(quaternion, dtype=np.float64)
    rotation = Rotation.from_quat(q.reshape(-1, 4)).as_matrix().reshape(q.shape[:-1] + (3, 3))
    out = np.zeros(rotation.shape[:-2] + (4, 4))
    out[..., :3, :3] = rotation
    out[..., :3, 3] = np.asarray(translation, dtype=np.float64)
    out[..., 3, 3] = 1.0
    return out


def split_transform(transform: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Homogeneous ``(..., 4, 4)`` -> (translation ``(..., 3)``, quaternion ``(..., 4)`` x, y, z, w), the quaternion
    signed canonically (w > 0, or at a half turn the first non-zero of x, y, z positive), as messages carry it."""
    transform = np.asarray(transform, dtype=np.float64)
    rotation = Rotation.from_matrix(transform[..., :3, :3].reshape(-1, 3, 3))
    return transform[..., :3, 3].copy(), rotation.as_quat(canonical=True).reshape(transform.shape[:-2] + (4,))


def invert_transform(transform: np.ndarray) -> np.ndarray:
    """Inverse of rigid transforms ``(..., 4, 4)`` (transpose the rotation, rotate back the translation)."""
    transform = np.asarray(transform, dtype=np.float64)
    rotation_t = np.swapaxes(transform[..., :3, :3], -1, -2)
    out = np.zeros_like(transform)
    out[..., :3, :3] = rotation_t
    out[..., :3, 3] = -np.einsum("...ij,...j->...i", rotation_t, transform[..., :3, 3])
    out[..., 3, 3] = 1.0
    return out


def interpolate_transform(
    stamp0: int, translation0: np.ndarray, quaternion0: np.ndarray,
    stamp1: int, translation1: np.ndarray, quaternion1: np.ndarray, stamp: int,
) -> np.ndarray:
    """Transform (4, 4) at ``stamp`` between two samples: lerp of the translation, slerp of the rotation (the
    shorter arc)."""
    weight = 0.0 if stamp1 == stamp0 else (stamp - stamp0) / (stamp1 - stamp0)
    translation = (1.0 - weight) * np.asarray(translation0) + weight * np.asarray(translation1)
    rotation = Slerp([0.0, 1.0], Rotation.from_quat([quaternion0, quaternion1]))(weight)
    return rigid_transform(translation, rotation.as_quat())


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
