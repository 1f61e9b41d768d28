"""``ReachableSet``: the cameras an arm can move to, as a grid of spheres around the object.

Angles follow :mod:`idpose_core.spherical` in the estimate's world: +z up (gravity where the views give it, else the
up the anchor's polar-angle parameter assumes), the anchor camera at azimuth 0.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class ReachableSet:
    """Candidate cameras: polar angles (degrees from up) in ``polar_deg``, azimuths (degrees from the anchor's,
    counter-clockwise seen from above) in ``azimuth_deg``, at a distance (m) clipped into ``distance``, on a grid of
    ``step_deg``. Raises ValueError for an empty or unordered range."""

    polar_deg: tuple[float, float] = (30.0, 100.0)
    azimuth_deg: tuple[float, float] = (-180.0, 180.0)
    distance: tuple[float, float] = (0.1, 3.0)
    step_deg: float = 10.0

    def __post_init__(self) -> None:
        for name, (low, high), limits in (("polar_deg", self.polar_deg, (0.0, 180.0)),
                                          ("azimuth_deg", self.azimuth_deg, (-360.0, 360.0)),
                                          ("distance", self.distance, (0.0, math.inf))):
            if not (limits[0] <= low <= high <= limits[1]) or (name == "distance" and low <= 0.0):
                raise ValueError(f"reachable {name} must be an ordered range within {limits} "
                                 f"({'positive' if name == 'distance' else 'inclusive'}), got ({low}, {high})")
        if self.azimuth_deg[1] - self.azimuth_deg[0] > 360.0:
            raise ValueError(f"reachable azimuth_deg spans more than a turn: {self.azimuth_deg}")
        if not 0.0 < self.step_deg <= 90.0:
            raise ValueError(f"reachable step_deg must be in (0, 90], got {self.step_deg}")

    def candidates(self, distance: float) -> np.ndarray:
        """Candidate cameras (M, 3) = (polar, azimuth, radius) in radians and metres, at ``distance`` clipped into
        the reachable range; a full turn of azimuth does not repeat its end."""
        radius = min(max(float(distance), self.distance[0]), self.distance[1])
        polars = _grid(*self.polar_deg, self.step_deg)
        low, high = self.azimuth_deg
        azimuths = _grid(low, high, self.step_deg)
        if high - low >= 360.0 - 1e-9:
            azimuths = azimuths[azimuths < low + 360.0 - 1e-9]
        polar, azimuth = np.meshgrid(np.radians(polars), np.radians(azimuths), indexing="ij")
        return np.stack([polar.ravel(), azimuth.ravel(), np.full(polar.size, radius)], axis=-1)


def _grid(low: float, high: float, step: float) -> np.ndarray:
    """Evenly spaced values from ``low`` to ``high`` inclusive, at most ``step`` apart (one value if equal)."""
    count = max(1, math.ceil((high - low) / step - 1e-9)) + 1 if high > low else 1
    return np.linspace(low, high, count)
