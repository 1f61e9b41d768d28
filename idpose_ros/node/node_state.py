"""What the node's rooms read of the node: its lifecycle state and its current parameters.

The node keeps one ``NodeState`` current (its transition callbacks set the state, its parameter callback the
values); the view intake and the estimation read it instead of calling back into the node.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from idpose_ros.node.lifecycle import Lifecycle
from idpose_ros.node.parameters import NodeSettings, node_settings


@dataclass
class NodeState:
    """The lifecycle state; every parameter's current value and the node's settings made from them."""

    values: dict[str, Any]
    lifecycle: Lifecycle = Lifecycle.UNCONFIGURED

    def __post_init__(self) -> None:
        self.settings: NodeSettings = node_settings(self.values)

    @property
    def active(self) -> bool:
        """Whether images and goals are taken now."""
        return self.lifecycle is Lifecycle.ACTIVE

    def update(self, values: dict[str, Any]) -> None:
        """New parameter values, and the settings made from them."""
        self.values, self.settings = values, node_settings(values)
