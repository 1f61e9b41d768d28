"""Pose hypotheses from every source, one verifier: the poses of views with depth, no learned prior needed.

``sources`` propose relative poses (global registration, gravity's yaw search, the arm's kinematics, the
diffusion estimate), ``pair`` refines and scores them on two views' depth (``verifier``), ``chain`` places
several views jointly, and ``verify_with_depth`` runs it all for a set of views. No ROS here.
"""
from idpose_core.pose_hypotheses.hypothesis import Hypothesis, ScoredHypothesis, Source
from idpose_core.pose_hypotheses.verification import VerificationSettings, verify_with_depth

__all__ = ["Hypothesis", "ScoredHypothesis", "Source", "VerificationSettings", "verify_with_depth"]
