"""seal_recording: make the flight recordings of a killed estimator node readable by rosbags and ``ros2 bag``.

A node killed (SIGKILL, power) leaves its recording without its end records. The node seals it itself when it
starts again on the same ``record_dir``; this command does it now, without the node: each recording named (or
found under a folder) is cut after its last whole record and given its end. Recordings a running node still
writes are left alone (they are locked), and whole ones are not touched.

    ros2 run idpose_ros seal_recording ~/.ros/idpose_records
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from idpose_ros.recording.sealing import recording_files, seal_recording


def main(argv: list[str] | None = None) -> int:
    """Exit code 0 when every recording is whole afterwards (or was in use), 1 when one is unreadable, 2 for
    bad arguments."""
    parser = argparse.ArgumentParser(prog="seal_recording", description=__doc__.split("\n\n")[0].split(": ", 1)[1])
    parser.add_argument("paths", type=Path, nargs="+", help="recording files, or folders holding them (record_dir)")
    args = parser.parse_args(argv)
    try:
        files = recording_files(args.paths)
    except (FileNotFoundError, ValueError) as err:
        print(f"seal_recording: error: {err}", file=sys.stderr)
        return 2
    if not files:
        print(f"seal_recording: no flight recording under {', '.join(map(str, args.paths))}", file=sys.stderr)
        return 2
    unreadable = 0
    for outcome in map(seal_recording, files):
        print(f"{outcome.path}: {outcome.status}" + (f" ({outcome.detail})" if outcome.detail else ""))
        unreadable += outcome.status == "unreadable"
    return 1 if unreadable else 0


if __name__ == "__main__":
    sys.exit(main())
