"""ROS 2 glue for ID-Pose: the estimator node (``node``), evaluation on bags (``evaluation``) and on data sets
(``dataset``), and the command-line tools (the modules beside them). No maths of its own."""
