"""Sealing the flight recordings a killed node left without an end, so that any mcap reader (rosbags, ``ros2 bag``)
reads them, without starting the node again."""
from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

from idpose_ros.recording.log_format import LIBRARY_PREFIX, is_recording, recordings_in
from idpose_ros.recording.mcap_log import RecordingInUse, RecordingUnreadable, scan_mcap, seal_mcap


@dataclass(frozen=True)
class SealOutcome:
    """What sealing did to one file: ``status`` is "sealed", "whole" (it had its end), "in use" (a running node
    writes it) or "unreadable"; ``detail`` says more."""

    path: Path
    status: str
    detail: str = ""


def recording_files(paths: Iterable[Path]) -> list[Path]:
    """The recordings named: files as given, folders searched at any depth. FileNotFoundError names a path that
    does not exist, ValueError a file that is not a flight recording."""
    files: list[Path] = []
    for path in map(Path, paths):
        if path.is_dir():
            files += recordings_in(path)
        elif not path.exists():
            raise FileNotFoundError(f"{path}: no such file or folder")
        elif not is_recording(path):
            raise ValueError(f"{path}: not a flight recording (an mcap file the estimator node wrote)")
        else:
            files.append(path)
    return files


def seal_recording(path: Path) -> SealOutcome:
    """Seal one recording after its last whole record; a file a running node holds is left alone."""
    try:
        scan = scan_mcap(path, LIBRARY_PREFIX)
        if scan.sealed:
            return SealOutcome(path, "whole")
        cut = scan.cut_bytes
        seal_mcap(path, scan)
    except RecordingInUse as err:
        return SealOutcome(path, "in use", str(err))
    except (RecordingUnreadable, OSError) as err:
        return SealOutcome(path, "unreadable", str(err))
    dropped = f", dropping the {cut} bytes of a record left half written" if cut else ""
    return SealOutcome(path, "sealed", f"{len(scan.messages)} messages kept{dropped}")
