"""Evaluating on bags: reading a bag's views and truth, the estimators (in process or through the node), the
report. The protocol itself is ``idpose_core.evaluation``; this package only feeds it."""
