"""Shared fixtures: DDS isolation for rclpy tests, the colcon workspace, a stand-in tf2_msgs and the tiny
Zero-1-to-3.

ROS_DOMAIN_ID is drawn at random (1..190, plus the pytest-xdist worker's number) and discovery kept on
this host when pytest imports this file, before any test calls rclpy.init, so concurrent test runs and
workers never see each other's nodes; subprocesses inherit both variables. Torch gets one OpenMP thread unless
OMP_NUM_THREADS says otherwise (set before torch is imported): on a busy 2-core machine, two
threads made the tiny model's steps 7-10x slower, worst on threads other than the main one.
"""
import ctypes
import os
import random
import shutil
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from scripts.install_interfaces import build_environment, cmake_arguments, prepend

# One draw per run (pytest-xdist workers inherit it from the controller) and one domain per worker in it.
os.environ.setdefault("IDPOSE_TEST_DOMAIN_BASE", str(random.SystemRandom().randint(1, 190)))
WORKER = int(os.environ.get("PYTEST_XDIST_WORKER", "gw0").removeprefix("gw"))
os.environ["ROS_DOMAIN_ID"] = str(int(os.environ["IDPOSE_TEST_DOMAIN_BASE"]) + WORKER)
os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
os.environ.setdefault("OMP_NUM_THREADS", "1")

ROOT = Path(__file__).resolve().parents[1]
# Fixtures that start ROS nodes or processes: a test that takes one is marked slow (``pytest_collection_modifyitems``).
NODE_OR_PROCESS_FIXTURES = {"ros_context", "harness", "colcon", "workspace", "tf2_msgs", "tf2_msgs_prefix"}
COLCON = Path(sys.executable).with_name("colcon")
# The ROS prefix this environment's ROS wheels installed (a pip-only install's stand-in for /opt/ros/jazzy).
ROS_PREFIX = Path(sys.prefix)
# The workspace command that builds this repository's two packages (docs/building.md).
WORKSPACE_BASE_PATHS = ("src", "src/idpose_ros/idpose_interfaces")


def run_colcon(*args: str, cwd: Path) -> str:
    """Run colcon from this environment in ``cwd``, with the build settings a sourced ROS setup gives CMake
    (ament_cmake packages find the ROS wheels as scripts/install_interfaces.py builds against them);
    fails the test with colcon's output on error."""
    result = subprocess.run(
        [str(COLCON), *args], cwd=cwd, capture_output=True, text=True, timeout=600,
        env={**build_environment(ROS_PREFIX), "COLCON_LOG_PATH": str(cwd / "log")},
    )
    assert result.returncode == 0, result.stdout + result.stderr
    return result.stdout


def colcon_build(ws: Path, *args: str) -> str:
    """``colcon build *args`` in ``ws``, CMake packages configured against this environment's ROS wheels."""
    return run_colcon("build", *args, "--cmake-args", *cmake_arguments(ROS_PREFIX), cwd=ws)


@pytest.fixture(scope="session")
def colcon() -> Callable[..., str]:
    """``colcon(*args, cwd=...)`` -> stdout."""
    return run_colcon


@pytest.fixture(scope="session")
def workspace(tmp_path_factory) -> Path:
    """A colcon workspace with this repository in ``src/idpose_ros``, both its packages (idpose_ros and
    idpose_interfaces) built once as a user builds them."""
    ws = tmp_path_factory.mktemp("ws")
    src = ws / "src" / "idpose_ros"
    shutil.copytree(ROOT, src, ignore=shutil.ignore_patterns(".venv", ".git", "build", "install", "log",
                                                             "__pycache__", ".pytest_cache", ".hypothesis"))
    colcon_build(ws, "--base-paths", *WORKSPACE_BASE_PATHS)
    return ws


@pytest.fixture(scope="session")
def tf2_msgs_prefix(tmp_path_factory) -> Path:
    """The install prefix of a stand-in ``tf2_msgs`` built with colcon in a temporary workspace, for tests only:
    PyPI has no tf2_msgs wheel. It holds TFMessage alone, with tf2_msgs' own one-line definition."""
    ws = tmp_path_factory.mktemp("tf2_msgs_ws")
    shutil.copytree(ROOT / "test" / "data" / "tf2_msgs", ws / "src" / "tf2_msgs")
    colcon_build(ws)
    return ws / "install" / "tf2_msgs"


@pytest.fixture
def tf2_msgs(tf2_msgs_prefix, monkeypatch) -> Path:
    """The stand-in tf2_msgs importable for one test, in this process and in the subprocesses it starts;
    yields its install prefix, and forgets the Python module afterwards.

    rosidl's C typesupport opens a message package's typesupport libraries by file name at run time, and
    the dynamic loader reads LD_LIBRARY_PATH only when a process starts: subprocesses get the library
    folder there, this process loads the libraries now (a library already loaded is found by its name)."""
    site = next(tf2_msgs_prefix.glob("lib/python3*/site-packages"))
    for library in sorted((tf2_msgs_prefix / "lib").glob("*.so")):
        ctypes.CDLL(str(library))
    monkeypatch.syspath_prepend(str(site))
    for name, path in (("PYTHONPATH", site), ("LD_LIBRARY_PATH", tf2_msgs_prefix / "lib"),
                       ("AMENT_PREFIX_PATH", tf2_msgs_prefix)):
        monkeypatch.setenv(name, prepend(str(path), os.environ.get(name)))
    yield tf2_msgs_prefix
    for module in [name for name in sys.modules if name == "tf2_msgs" or name.startswith("tf2_msgs.")]:
        del sys.modules[module]


@pytest.fixture(scope="session")
def tiny_model_dir(tmp_path_factory) -> Path:
    """The tiny random Zero-1-to-3 (seed 0) saved as a diffusers folder, for ``model_path``."""
    from idpose_core.zero123 import Zero123Predictor

    path = tmp_path_factory.mktemp("tiny_zero123")
    Zero123Predictor.tiny(seed=0).save_pretrained(path)
    return path


@pytest.fixture(scope="module")
def ros_context():
    """An rclpy context of its own per test module (no signal handlers: pytest keeps Ctrl-C)."""
    import rclpy
    from rclpy.context import Context
    from rclpy.signals import SignalHandlerOptions

    context = Context()
    rclpy.init(context=context, signal_handler_options=SignalHandlerOptions.NO)
    yield context
    rclpy.shutdown(context=context)


def poll_until(predicate: Callable[[], Any], what: str, timeout: float = 60.0, poll: float = 0.02) -> Any:
    """Poll ``predicate`` every ``poll`` s until it returns something truthy (returned); fails naming ``what``."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        value = predicate()
        if value:
            return value
        time.sleep(poll)
    raise AssertionError(f"timed out after {timeout} s waiting for {what}")


@pytest.fixture(scope="session")
def wait_for() -> Callable[..., Any]:
    """``wait_for(predicate, what, timeout=60)``: for tests that wait on ROS traffic."""
    return poll_until


@pytest.fixture(scope="session")
def object_views() -> list[tuple[Any, Any]]:
    """Four 64 px renders of a demo object, (RGB uint8 on white, alpha uint8), polar 70-95 deg around it."""
    import numpy as np

    from idpose_core.synthetic.scenes import SceneRenderer, demo_objects

    with SceneRenderer(demo_objects()[0], image_size=64) as renderer:
        return [(rgb, (mask * 255).astype(np.uint8))
                for rgb, mask in (renderer.render(np.radians(polar), np.radians(azimuth), 2.0)
                                  for polar, azimuth in ((80, 0), (85, 90), (70, 200), (95, 300)))]


def png_chunk(kind: bytes, body: bytes) -> bytes:
    """One png chunk: length, type, body, CRC."""
    import struct
    import zlib

    return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body))


@pytest.fixture(scope="session")
def png_bomb() -> bytes:
    """A valid 140 KB grey png that decodes to 12000 x 12000 pixels (144 MB grey, 432 MB as RGB)."""
    import struct
    import zlib

    side, rows_per_block = 12000, 500
    compressor = zlib.compressobj(9)
    block = bytes((side + 1) * rows_per_block)  # each row: filter byte 0, then black pixels
    data = b"".join(compressor.compress(block) for _ in range(side // rows_per_block)) + compressor.flush()
    header = struct.pack(">IIBBBBB", side, side, 8, 0, 0, 0, 0)  # 8-bit greyscale, no interlace
    return b"\x89PNG\r\n\x1a\n" + png_chunk(b"IHDR", header) + png_chunk(b"IDAT", data) + png_chunk(b"IEND", b"")


@pytest.fixture(scope="session")
def errors_of() -> Callable[[Any], Any]:
    """noise_error of a predictor on fixed inputs: equal outputs mean equal weights and conditioning."""
    import torch

    def errors(predictor):
        generator = torch.Generator().manual_seed(0)
        views = predictor.encode(torch.rand(2, 3, 32, 32, generator=generator) * 2 - 1)
        noise = torch.randn(2, *views.noise_shape, generator=generator)
        pose = torch.tensor([[0.3, 1.0, 0.1], [-0.2, 4.0, 0.0]])
        return predictor.noise_error(views, torch.tensor([0, 1]), torch.tensor([1, 0]), pose,
                                     torch.tensor([200, 205]), noise)

    return errors


@pytest.fixture
def harness(ros_context, tiny_model_dir, wait_for, request):
    """A node per test, in a namespace of its own, with the tiny model and the fast solver (``node_harness``)."""
    from node_harness import FAST_SOLVER, Harness

    made = []

    def make(**overrides: Any) -> Harness:
        settings = {"model_path": str(tiny_model_dir), **FAST_SOLVER, **overrides}
        made.append(Harness(ros_context, wait_for, f"/{request.node.name.split('[')[0]}_{len(made)}", **settings))
        return made[-1]

    yield make
    for h in made:
        h.close()


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """``-m "not slow"`` is the fast lane: refuse a test that starts a node or a process through a fixture unless it
    is marked slow (a marker forgotten would put minutes into the fast lane)."""
    unmarked = [item.nodeid for item in items if NODE_OR_PROCESS_FIXTURES & set(getattr(item, "fixturenames", ()))
                and item.get_closest_marker("slow") is None]
    if unmarked:
        raise pytest.UsageError("mark these tests @pytest.mark.slow (they start a node or a process): "
                                + ", ".join(unmarked))
