"""ROS 2 glue for ID-Pose: the estimator node and the command-line tools. No maths of its own."""
