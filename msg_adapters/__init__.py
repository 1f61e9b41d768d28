"""ROS messages <-> numpy: images, compressed images, poses, pose arrays and RViz markers.

Imports numpy, OpenCV and the ROS message packages only (no torch, no idpose_core), so the
node's message handling can be tested and reused without a model.
"""
