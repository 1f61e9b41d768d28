"""Data sets: many inputs (bags, the official layout) evaluated on Ray with a resumable log and a merged
report, and synthetic bags rendered with pybullet."""
