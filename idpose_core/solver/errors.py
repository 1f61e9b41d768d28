"""Errors the solver raises besides ``ValueError`` for bad input."""


class Cancelled(Exception):
    """The caller's cancel event was set; the solver stopped before its next predictor call."""
