"""The ID-Pose solver: relative camera poses of sparse views by inverting a ``NoisePredictor``."""
from idpose_core.cancellation import Cancelled
from idpose_core.solver.config import SolverConfig
from idpose_core.solver.context import Progress
from idpose_core.solver.estimate import estimate_poses
from idpose_core.solver.result import SolverResult

__all__ = ["Cancelled", "Progress", "SolverConfig", "SolverResult", "estimate_poses"]
