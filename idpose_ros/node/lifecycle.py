"""The estimator's lifecycle state as an enum, with rclpy's labels (what /diagnostics reports as ``lifecycle``).

rclpy Jazzy's ``LifecycleNode`` has no public accessor for its current state: only the private ``_state_machine``
and the ``~/get_state`` service, which a node cannot call on itself. So the node records the state in its own
transition callbacks (``on_configure``, ``on_activate``, ...), the public way.
"""
from __future__ import annotations

from enum import StrEnum


class Lifecycle(StrEnum):
    """A primary lifecycle state, or the transition state the node is in while a transition's callback runs."""

    UNCONFIGURED = "unconfigured"
    INACTIVE = "inactive"
    ACTIVE = "active"
    FINALIZED = "finalized"
    CONFIGURING = "configuring"
    CLEANINGUP = "cleaningup"
    SHUTTINGDOWN = "shuttingdown"
    ACTIVATING = "activating"
    DEACTIVATING = "deactivating"
    ERRORPROCESSING = "errorprocessing"
