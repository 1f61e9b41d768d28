"""The result's ViewEstimate fields are plain Python values: rclpy's C conversion aborts the whole process (not
raises) on a numpy bool or float32 in a bool or float field, so the boundary converts what the core computes in
numpy."""
from __future__ import annotations

import numpy as np
from rclpy.serialization import deserialize_message, serialize_message

from idpose_core.depth_fusion import ViewRefinement
from idpose_interfaces.msg import ViewEstimate
from idpose_ros.estimate_result import depth_fields, refinement_of


def numpy_refinement() -> ViewRefinement:
    """A verifier's report as numpy computes it: numpy bools and floats where the message wants Python ones."""
    return ViewRefinement(np.True_, "runner-up within 0.65 of the best", np.float32(0.49), np.float64(0.004),
                          np.float64(140.6), np.float32(0.95), "registration", np.float64(0.65), np.True_,
                          np.False_, np.float64(3.0))


def test_depth_fields_are_python_bools_and_floats():
    fields = depth_fields(numpy_refinement())
    wrong = {name: type(value).__name__ for name, value in fields.items() if type(value) not in (bool, float, str)}
    assert not wrong, f"numpy values reach the message: {wrong}"


def test_a_view_estimate_from_numpy_values_serialises_and_reads_back():
    view = ViewEstimate(ambiguous=True, **depth_fields(numpy_refinement()))
    back = deserialize_message(serialize_message(view), ViewEstimate)
    refinement = refinement_of(back)
    assert refinement is not None and refinement.refined and refinement.ambiguous
    assert refinement.source == "registration" and abs(refinement.margin - 0.65) < 1e-6
