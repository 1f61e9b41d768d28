"""Shared fixtures: DDS isolation for rclpy tests, the colcon workspace and the tiny Zero-1-to-3.

ROS_DOMAIN_ID is drawn at random (1..200) and discovery kept on this host when pytest imports
this file, before any test calls rclpy.init, so concurrent test runs on the machine never see
each other's nodes; subprocesses inherit both variables. Torch gets one OpenMP thread unless
OMP_NUM_THREADS says otherwise (set before torch is imported): on a busy 2-core machine, two
threads made the tiny model's steps 7-10x slower, worst on threads other than the main one.
"""
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

os.environ["ROS_DOMAIN_ID"] = str(random.SystemRandom().randint(1, 200))
os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
os.environ.setdefault("OMP_NUM_THREADS", "1")

ROOT = Path(__file__).resolve().parents[1]
COLCON = Path(sys.executable).with_name("colcon")


def run_colcon(*args: str, cwd: Path) -> str:
    """Run colcon from this environment in ``cwd``; fails the test with colcon's output on error."""
    result = subprocess.run(
        [str(COLCON), *args], cwd=cwd, capture_output=True, text=True, timeout=600,
        env={**os.environ, "COLCON_LOG_PATH": str(cwd / "log")},
    )
    assert result.returncode == 0, result.stdout + result.stderr
    return result.stdout


@pytest.fixture(scope="session")
def colcon() -> Callable[..., str]:
    """``colcon(*args, cwd=...)`` -> stdout."""
    return run_colcon


@pytest.fixture(scope="session")
def workspace(tmp_path_factory) -> Path:
    """A colcon workspace with this repository as its only package, built once as a user builds it."""
    ws = tmp_path_factory.mktemp("ws")
    src = ws / "src" / "idpose_ros"
    shutil.copytree(ROOT, src, ignore=shutil.ignore_patterns(".venv", ".git", "build", "install", "log",
                                                             "__pycache__", ".pytest_cache", ".hypothesis"))
    run_colcon("build", "--packages-select", "idpose_ros", cwd=ws)
    return ws


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


def poll_until(predicate: Callable[[], Any], what: str, timeout: float = 60.0) -> Any:
    """Poll ``predicate`` every 20 ms until it returns something truthy (returned); fails naming ``what``."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        value = predicate()
        if value:
            return value
        time.sleep(0.02)
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
