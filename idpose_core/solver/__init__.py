"""The ID-Pose solver: relative camera poses of sparse views by inverting a ``NoisePredictor``."""
from idpose_core.cancellation import Cancelled
from idpose_core.solver.config import SolverConfig
from idpose_core.solver.context import Progress, SampleCount
from idpose_core.solver.estimate import STAGES, estimate_fraction, estimate_poses
from idpose_core.solver.result import SolverResult

__all__ = ["STAGES", "Cancelled", "Progress", "SampleCount", "SolverConfig", "SolverResult", "estimate_fraction",
           "estimate_poses"]
