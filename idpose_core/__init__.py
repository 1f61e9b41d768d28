"""ID-Pose core: geometry, preprocessing, the noise-predictor protocol and its models, the solver.

Pure Python, numpy and torch. Never imports ROS, so it runs in notebooks, batch jobs and tests alike.
"""
