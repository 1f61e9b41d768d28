"""Synthetic object scenes (pybullet) and the render oracle used to test and benchmark the solver."""
