"""How many camera frames reach a subscriber in another process, per Fast DDS transport setting and QoS.

Usage (from the repository root): .venv/bin/python bench/image_transport.py [--seconds 10] [--rate 30] [--repeat 3]
       ... --role publish --payload "rgb8 1920x1080" --topic <topic>   stream to <topic> alone (the
       estimator's load tests use it to stream HD frames from a process of their own)

A bare rclpy publisher (a camera driver's stand-in, reliable like rclpy's default) streams frames
(raw rgb8 1920x1080, 6.2 MB each, and jpeg 1280x720) at ``--rate`` Hz; a bare rclpy subscriber in
another process counts the distinct frames it receives and how old they are on arrival. Cases:
Fast DDS's default transports; ``FASTDDS_BUILTIN_TRANSPORTS=LARGE_DATA``; and the shipped profile
``config/fastdds_large_images.xml`` (shared-memory segment of 32 MB) for the publisher, the
subscriber or both; each with a best-effort subscription (sensor data, what the estimator uses) and
a reliable one. Every case runs ``--repeat`` times, the rounds interleaved so that a change of load
on the machine touches every case alike. No node of this project is involved. Prints a table and
writes ``bench/results/image_transport/image_transport.json``. Not a test: the figures depend on the machine and its
load.
"""
from __future__ import annotations

import argparse
import json
import os
import random
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # run as a script from a checkout

from bench.result_files import result_path  # noqa: E402

RESULT = result_path("image_transport")
PROFILE = ROOT / "config" / "fastdds_large_images.xml"
TOPIC = "bench_frames"
PAYLOADS = {"rgb8 1920x1080": ("raw", 1920, 1080), "jpeg 1280x720": ("jpeg", 1280, 720)}
LARGE_DATA = {"FASTDDS_BUILTIN_TRANSPORTS": "LARGE_DATA"}
LARGE_SHM = {"FASTRTPS_DEFAULT_PROFILES_FILE": str(PROFILE)}
TRANSPORTS = {  # name: (publisher's environment, subscriber's environment)
    "default": ({}, {}),
    "LARGE_DATA, both": (LARGE_DATA, LARGE_DATA),
    "large SHM profile, publisher": (LARGE_SHM, {}),
    "large SHM profile, subscriber": ({}, LARGE_SHM),
    "large SHM profile, both": (LARGE_SHM, LARGE_SHM),
}
RAW = "rgb8 1920x1080"
CASES = [(RAW, "default", "best_effort"), (RAW, "default", "reliable"), (RAW, "LARGE_DATA, both", "best_effort"),
         (RAW, "LARGE_DATA, both", "reliable"), (RAW, "large SHM profile, subscriber", "best_effort"),
         (RAW, "large SHM profile, publisher", "best_effort"), (RAW, "large SHM profile, both", "best_effort"),
         (RAW, "large SHM profile, both", "reliable"), ("jpeg 1280x720", "default", "best_effort")]
MATCH_TIMEOUT = 20.0  # s for publisher and subscriber to discover each other
DRAIN = 2.0  # s the subscriber keeps listening after the last frame


def frames(payload: str, width: int, height: int):
    """One message to publish again and again (the payload's content does not matter to the transport)."""
    import cv2
    import numpy as np
    from sensor_msgs.msg import CompressedImage, Image

    rng = np.random.default_rng(0)
    pixels = cv2.GaussianBlur(rng.integers(0, 256, (height, width, 3), dtype=np.uint8), (0, 0), 3)
    if payload == "raw":
        return Image(height=height, width=width, encoding="rgb8", step=3 * width, data=pixels.tobytes())
    ok, encoded = cv2.imencode(".jpg", pixels)
    assert ok
    return CompressedImage(format="rgb8; jpeg compressed bgr8", data=encoded.tobytes())


def publish(payload: str, width: int, height: int, seconds: float, rate: float, topic: str = TOPIC) -> dict:
    """Wait for a subscriber, then send seconds x rate frames at rate Hz, each with its own header.stamp."""
    import rclpy
    from rclpy.qos import QoSProfile
    from sensor_msgs.msg import CompressedImage, Image

    rclpy.init()
    node = rclpy.create_node("bench_publisher")
    msg = frames(payload, width, height)
    msg.header.frame_id = "camera_optical"
    publisher = node.create_publisher(Image if payload == "raw" else CompressedImage, topic, QoSProfile(depth=10))
    deadline = time.monotonic() + MATCH_TIMEOUT
    while publisher.get_subscription_count() == 0 and time.monotonic() < deadline:
        time.sleep(0.05)
    time.sleep(0.5)  # let the subscriber's side of the match settle too
    count = int(seconds * rate)
    start = time.monotonic()
    for index in range(count):
        time.sleep(max(0.0, start + index / rate - time.monotonic()))
        msg.header.stamp = node.get_clock().now().to_msg()
        publisher.publish(msg)
    sent_seconds = time.monotonic() - start
    node.destroy_node()
    rclpy.shutdown()
    return {"sent": count, "send_seconds": round(sent_seconds, 2)}


def subscribe(payload: str, subscription: str, seconds: float) -> dict:
    """Count distinct frames and their age on arrival until the stream has been quiet for DRAIN s."""
    import rclpy
    from rclpy.qos import QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
    from sensor_msgs.msg import CompressedImage, Image

    rclpy.init()
    node = rclpy.create_node("bench_subscriber")
    received: set[tuple[int, int]] = set()
    ages: list[float] = []
    last = [time.monotonic()]

    def on_frame(msg) -> None:
        received.add((msg.header.stamp.sec, msg.header.stamp.nanosec))
        now = node.get_clock().now().nanoseconds
        ages.append((now - (msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec)) * 1e-9)
        last[0] = time.monotonic()

    qos = qos_profile_sensor_data if subscription == "best_effort" else QoSProfile(
        depth=5, reliability=ReliabilityPolicy.RELIABLE)
    node.create_subscription(Image if payload == "raw" else CompressedImage, TOPIC, on_frame, qos)
    deadline = time.monotonic() + MATCH_TIMEOUT + seconds + 30.0
    while rclpy.ok() and time.monotonic() < deadline:
        rclpy.spin_once(node, timeout_sec=0.1)
        if received and time.monotonic() - last[0] > DRAIN:
            break
    node.destroy_node()
    rclpy.shutdown()
    return {"received": len(received), "median_age_ms": round(1000 * statistics.median(ages), 1) if ages else None}


def run_case(payload_name: str, transport: str, subscription: str, seconds: float, rate: float) -> dict:
    """One publisher and one subscriber process on a fresh domain, with the transport's environment each."""
    publisher_env, subscriber_env = TRANSPORTS[transport]
    base = {**os.environ, "ROS_DOMAIN_ID": str(random.SystemRandom().randint(1, 200)),
            "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}
    for name in (*LARGE_DATA, *LARGE_SHM):
        base.pop(name, None)
    common = [sys.executable, __file__, "--payload", payload_name, "--seconds", str(seconds), "--rate", str(rate)]
    subscriber = subprocess.Popen([*common, "--role", "subscribe", "--subscription", subscription],
                                  env={**base, **subscriber_env}, stdout=subprocess.PIPE, text=True)
    publisher = subprocess.Popen([*common, "--role", "publish"], env={**base, **publisher_env},
                                 stdout=subprocess.PIPE, text=True)
    sent = json.loads(publisher.communicate()[0].strip().splitlines()[-1])
    got = json.loads(subscriber.communicate()[0].strip().splitlines()[-1])
    delivered = got["received"] / sent["sent"]
    return {"payload": payload_name, "transport": transport, "subscription": subscription, **sent, **got,
            "delivered_percent": round(100 * delivered, 1)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--rate", type=float, default=30.0)
    parser.add_argument("--repeat", type=int, default=3, help="runs per case")
    parser.add_argument("--role", choices=("publish", "subscribe"), help="one side only (run_case starts both)")
    parser.add_argument("--topic", default=TOPIC, help="topic of --role publish")
    parser.add_argument("--payload", choices=sorted(PAYLOADS), help="payload of --role publish or subscribe")
    parser.add_argument("--subscription", choices=("best_effort", "reliable"), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.role == "publish":
        print(json.dumps(publish(*PAYLOADS[args.payload], args.seconds, args.rate, args.topic)))
        return
    if args.role == "subscribe":
        print(json.dumps(subscribe(PAYLOADS[args.payload][0], args.subscription, args.seconds)))
        return
    runs = [run_case(*case, args.seconds, args.rate) for _ in range(args.repeat) for case in CASES]
    rows = [summary(case, [run for run in runs if (run["payload"], run["transport"], run["subscription"]) == case])
            for case in CASES]
    print(f"{'payload':16} {'transport':30} {'subscription':12} {'sent':>5} {'delivered (each run)':>22} "
          f"{'median age':>10}")
    for row in rows:
        each = " ".join(f"{percent:.0f}" for percent in row["delivered_percent_each"])
        age = f"{row['median_age_ms']} ms" if row["median_age_ms"] is not None else "-"
        print(f"{row['payload']:16} {row['transport']:30} {row['subscription']:12} {row['sent']:5d} "
              f"{row['delivered_percent']:6.0f}% ({each:>12}) {age:>10}")
    load = os.getloadavg()
    RESULT.write_text(json.dumps({"seconds": args.seconds, "rate": args.rate, "repeat": args.repeat,
                                  "cpus": os.cpu_count(), "load_average": [round(x, 2) for x in load],
                                  "cases": rows, "runs": runs}, indent=2) + "\n")
    print(f"written to {RESULT.relative_to(ROOT)}")


def summary(case: tuple[str, str, str], runs: list[dict]) -> dict:
    """One case over its runs: the median delivered share and age, and every run's share."""
    ages = [run["median_age_ms"] for run in runs if run["median_age_ms"] is not None]
    return {"payload": case[0], "transport": case[1], "subscription": case[2], "sent": runs[0]["sent"],
            "delivered_percent": statistics.median(run["delivered_percent"] for run in runs),
            "delivered_percent_each": [run["delivered_percent"] for run in runs],
            "median_age_ms": round(statistics.median(ages), 1) if ages else None}


if __name__ == "__main__":
    main()
