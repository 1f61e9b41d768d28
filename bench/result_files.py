"""Where each benchmark keeps what it measured: ``bench/results/<benchmark>/``, one folder per benchmark."""
from __future__ import annotations

from pathlib import Path

RESULTS = Path(__file__).resolve().parent / "results"


def result_path(benchmark: str, name: str = "") -> Path:
    """``bench/results/<benchmark>/<name>``; ``name`` defaults to ``<benchmark>.json``."""
    return RESULTS / benchmark / (name or f"{benchmark}.json")
