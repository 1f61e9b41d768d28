"""Where to look next: the camera that best settles an uncertain estimate, within the arm's reach.

``ReachableSet`` gives the candidate cameras; ``suggest_next_view`` scores them against the estimate's competing
hypotheses (each ambiguous view's answer and runner-up) or, when nothing is ambiguous, against coverage. No ROS.
"""
from idpose_core.next_view.reachable import ReachableSet
from idpose_core.next_view.suggestion import CRITERIA, NextView, pose_spheres, suggest_next_view, view_spheres

__all__ = ["CRITERIA", "NextView", "ReachableSet", "pose_spheres", "suggest_next_view", "view_spheres"]
