"""Full ros2msg definitions of the recorded message types, for the mcap schemas rosbags reads back.

The ROS 2 Jazzy types come from rosbags' typestore; the node's own (``idpose_interfaces``: the
EstimatePoses result and its messages) are registered from the interface package's installed
.msg and .action files (``<prefix>/share/idpose_interfaces``, beside ``<prefix>/lib/python3.X/site-packages``:
the same in a venv, a colcon workspace and a ROS installation).
"""
from __future__ import annotations

from functools import cache
from pathlib import Path

from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.store import Typestore

import idpose_interfaces

INTERFACES = "idpose_interfaces"


def interface_share() -> Path:
    """Where idpose_interfaces' .msg and .action files are installed; FileNotFoundError names the place."""
    share = Path(idpose_interfaces.__file__).resolve().parents[4] / "share" / INTERFACES
    if not (share / "action").is_dir():
        raise FileNotFoundError(f"the idpose_interfaces definitions are not installed at {share}")
    return share


@cache
def typestore() -> Typestore:
    """The ROS 2 Jazzy types and idpose_interfaces' messages and action result."""
    store = get_typestore(Stores.ROS2_JAZZY)
    share = interface_share()
    types = {}
    own = {path.stem for path in (share / "msg").glob("*.msg")}
    for path in sorted((share / "msg").glob("*.msg")):
        types.update(get_types_from_msg(path.read_text(), f"{INTERFACES}/msg/{path.stem}"))
    for path in sorted((share / "action").glob("*.action")):
        result = path.read_text().split("\n---\n")[1]  # goal, result, feedback; own types named in full
        result = "\n".join(f"{INTERFACES}/msg/{line}" if line.split(" ")[0].rstrip("[]") in own else line
                           for line in result.splitlines())
        types.update(get_types_from_msg(result, f"{INTERFACES}/action/{path.stem}_Result"))
    store.register(types)
    return store


@cache
def message_definition(msgtype: str) -> str:
    """The full ros2msg definition of ``msgtype`` (``pkg/msg/Name``), its dependencies appended as rosbag2 does."""
    return typestore().generate_msgdef(msgtype, ros_version=2)[0]


def msgtype_of(message: object) -> str:
    """``pkg/msg/Name`` (or ``pkg/action/Name``) of an rclpy message instance."""
    module = type(message).__module__.split(".")
    return f"{module[0]}/{module[1]}/{type(message).__name__}"
