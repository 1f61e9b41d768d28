"""The flight recorder's cost and bounds: ms and bytes per kept 1080p view, and a soak of the node recording.

``--part cost`` records ``--views`` kept views (1920x1080 rgb8 with a 16UC1 depth and CameraInfo, as
a RealSense gives them) through ``FlightRecorder`` as the node calls it, and prints the mean and worst
ms and the bytes per view. ``--part soak`` starts the node (``record_dir``, auto capture every
``--interval`` s, ``record_max_bytes`` = ``--max-bytes``), streams raw 1080p frames at ``--rate`` Hz for
``--seconds`` s, resets the buffer whenever it is full, and prints the node's RSS and the recording
folder's size every 30 s: both must level off (rotation keeps each file under the bound; the folder
grows by files, which the user clears). Figures go to stdout; run it once, not in a loop.
"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from builtin_interfaces.msg import Time  # noqa: E402
from rclpy.serialization import serialize_message  # noqa: E402
from std_msgs.msg import Header  # noqa: E402

from idpose_ros.node.flight_recorder import FlightRecorder, restored_view  # noqa: E402
from idpose_ros.view_decoding import ViewMessages  # noqa: E402
from msg_adapters import array_to_image, depth_to_image, matrix_to_camera_info  # noqa: E402

WIDTH, HEIGHT = 1920, 1080


def hd_view(seed: int) -> ViewMessages:
    rng = np.random.default_rng(seed)
    head = Header(stamp=Time(sec=seed, nanosec=0), frame_id="camera_color_optical_frame")
    image = array_to_image(rng.integers(0, 255, (HEIGHT, WIDTH, 3), dtype=np.uint8), "rgb8", head)
    depth = depth_to_image(rng.uniform(0.3, 2.0, (HEIGHT, WIDTH)).astype(np.float32), "16UC1", head)
    info = matrix_to_camera_info(np.array([[1380.0, 0, 960], [0, 1380.0, 540], [0, 0, 1]]), WIDTH, HEIGHT, head)
    return ViewMessages(image, depth, None, info)


def cost(views: int) -> None:
    """Per kept view: what the keeping callback waits (queueing it) and what the writer thread spends, and after
    the last one how long a ``flush`` (what ~/capture waits before it answers) takes."""
    with tempfile.TemporaryDirectory() as folder:
        kept = []
        recorder = FlightRecorder(folder, 2_000_000_000, lambda: list(kept), lambda _: None, print)
        recorder.start(False, {"node": "bench"})
        callback, flushes, serializing = [], [], []
        for k in range(views):
            view = restored_view(hd_view(k))
            kept.append(view)
            started = time.perf_counter()
            for message in (view.received.image, view.received.depth, view.received.camera_info):
                serialize_message(message)
            serializing.append(time.perf_counter() - started)
            started = time.perf_counter()
            recorder.view_kept(len(kept), view)
            callback.append(time.perf_counter() - started)
            recorder.flush()  # one view at a time: the writer's seconds are its own, not a backlog's
            flushes.append(time.perf_counter() - started)
        recorder.close()
    ms, flush_ms = 1000 * np.array(callback), 1000 * np.array(flushes)
    written = recorder.cost
    print(f"cost per kept 1080p view (rgb8 + 16UC1 depth + CameraInfo), {views} views: the callback waits mean "
          f"{ms.mean():.2f} ms, worst {ms.max():.2f} ms; the writer thread spends mean "
          f"{1000 * written.seconds / written.views:.1f} ms, of which serializing the messages "
          f"{1000 * np.mean(serializing):.1f} ms (the rest is the file write); kept until written (what "
          f"~/capture waits) mean "
          f"{flush_ms.mean():.1f} ms, median {np.median(flush_ms):.1f} ms, worst {flush_ms.max():.1f} ms; "
          f"{written.bytes // written.views} bytes")


def rss_kb(pid: int) -> int:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1])
    return 0


def folder_bytes(folder: Path) -> tuple[int, int]:
    files = list(folder.glob("idpose_*.mcap"))
    return sum(path.stat().st_size for path in files), len(files)


def soak(seconds: float, rate: float, interval: float, max_bytes: int) -> None:
    import rclpy
    from rclpy.node import Node
    from sensor_msgs.msg import Image
    from std_srvs.srv import Trigger

    env = {**os.environ, "FASTRTPS_DEFAULT_PROFILES_FILE": str(ROOT / "config" / "fastdds_large_images.xml"),
           "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST", "OMP_NUM_THREADS": "1"}
    env.setdefault("ROS_DOMAIN_ID", str(100 + os.getpid() % 100))
    os.environ.update(env)
    folder = Path(tempfile.mkdtemp(prefix="idpose_soak_"))
    node = subprocess.Popen([sys.executable, "-m", "idpose_ros.node.process", "--ros-args",
                             "-r", "__ns:=/soak", "-p", f"record_dir:={folder}", "-p", f"record_max_bytes:={max_bytes}",
                             "-p", f"min_view_interval:={interval}", "-p", "max_views:=8"],
                            cwd=ROOT, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    rclpy.init()
    probe = Node("soak_probe", namespace="/soak")
    images = probe.create_publisher(Image, "image", 10)
    reset = probe.create_client(Trigger, "idpose_estimator/reset")
    frame = array_to_image(np.random.default_rng(0).integers(0, 255, (HEIGHT, WIDTH, 3), dtype=np.uint8), "rgb8",
                           Header(frame_id="camera"))
    try:
        while images.get_subscription_count() == 0:
            rclpy.spin_once(probe, timeout_sec=0.1)
        print(f"soak: node pid {node.pid}, RSS {rss_kb(node.pid) / 1024:.0f} MB before the stream; {folder}")
        started = last_report = time.monotonic()
        sent = 0
        while (now := time.monotonic()) - started < seconds:
            frame.header.stamp = probe.get_clock().now().to_msg()
            images.publish(frame)
            sent += 1
            if sent % int(8 * interval * rate + rate) == 0:
                reset.call_async(Trigger.Request())  # the buffer holds 8 views: start the next object
            rclpy.spin_once(probe, timeout_sec=0.0)
            if now - last_report >= 30.0:
                size, files = folder_bytes(folder)
                print(f"t={now - started:5.0f} s: {sent} frames sent, node RSS {rss_kb(node.pid) / 1024:.0f} MB, "
                      f"recording {size / 1e6:.0f} MB in {files} files (largest "
                      f"{max(p.stat().st_size for p in folder.glob('idpose_*.mcap')) / 1e6:.0f} MB)", flush=True)
                last_report = now
            time.sleep(max(0.0, started + sent / rate - time.monotonic()))
        size, files = folder_bytes(folder)
        print(f"end after {seconds:.0f} s: {sent} frames, node RSS {rss_kb(node.pid) / 1024:.0f} MB, recording "
              f"{size / 1e6:.0f} MB in {files} files, none above record_max_bytes + one view "
              f"({max(p.stat().st_size for p in folder.glob('idpose_*.mcap')) / 1e6:.0f} MB largest)")
    finally:
        node.terminate()
        node.wait(timeout=30)
        probe.destroy_node()
        rclpy.shutdown()
        for path in folder.glob("*"):
            path.unlink()
        folder.rmdir()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--part", choices=("cost", "soak"), required=True)
    parser.add_argument("--views", type=int, default=20)
    parser.add_argument("--seconds", type=float, default=600.0)
    parser.add_argument("--rate", type=float, default=10.0)
    parser.add_argument("--interval", type=float, default=1.0)
    parser.add_argument("--max-bytes", type=int, default=200_000_000)
    args = parser.parse_args()
    if args.part == "cost":
        cost(args.views)
    else:
        soak(args.seconds, args.rate, args.interval, args.max_bytes)


if __name__ == "__main__":
    main()
