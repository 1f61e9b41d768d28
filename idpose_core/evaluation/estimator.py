"""What the protocol asks of an estimator: n decoded views in, the node's poses and confidences out."""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from idpose_core.depth_fusion import ObjectCloud
from idpose_core.solver import Progress
from idpose_core.view_input import ViewInput


@dataclass(frozen=True)
class ViewSetEstimate:
    """What an estimator returns for n views: what the node publishes, and the solver's confidence.

    ``poses`` (n, 4, 4) optical camera poses in the anchor camera's frame (poses[0] = identity);
    ``scores`` and ``ambiguous`` (n-1,) per non-anchor view; ``seconds`` the wall time of the estimate;
    ``details`` what the estimate read off its views (JSON-ready: how masks were made, gravity's polar
    angles and rolls, the depth distance, where the anchor's polar angle and distance came from). An estimator
    that runs the pipeline in this process also gives ``masks``, n bool (H_k, W_k) object masks in each view's
    own image, and ``crops`` (n, S, S, 3) uint8, the preprocessed images the model saw (empty otherwise).
    ``cloud``: the object's points fused in the anchor's frame, where the anchor had depth (None otherwise).
    """

    poses: np.ndarray
    scores: np.ndarray
    ambiguous: np.ndarray
    seconds: float
    details: dict[str, Any] = field(default_factory=dict)
    masks: tuple[np.ndarray, ...] = ()
    crops: np.ndarray | None = None
    cloud: ObjectCloud | None = None


class ViewSetEstimator(Protocol):
    """Estimates the poses of n views (the first is the anchor) given the anchor's polar angle and distance
    (a view's gravity and the anchor's depth, when given, take precedence).

    ``values`` are the node parameters it runs on; ``description`` says what estimates (mode, model,
    node); ``close()`` releases what it holds (a node, a ROS context).
    """

    values: dict[str, Any]
    description: dict[str, Any]

    def __call__(self, views: Sequence[ViewInput], anchor_polar_deg: float, object_distance: float,
                 progress: Progress | None = None) -> ViewSetEstimate: ...

    def close(self) -> None: ...
