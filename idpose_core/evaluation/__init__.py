"""The paper's evaluation protocol, as a library that knows no command line and no ROS.

``picks`` draws the view sets, ``protocol`` plans the estimates (``EstimateTask``), ``run`` runs one
estimate with any ``ViewSetEstimator`` (and the classical and random baselines on the same views),
``scoring`` scores it against the true cameras, ``results`` gathers an evaluation. Readers of bags,
of the official data layout and the node replay (in ``idpose_ros``) only feed it ``ViewInput``s.
"""
