"""The estimator's view buffer: decoded images kept in capture order, the first one the anchor.

Thread-safe, because image callbacks, services and the estimation worker all touch it.
"""
from __future__ import annotations

import threading
from dataclasses import dataclass

from builtin_interfaces.msg import Time

from idpose_core.pipeline import ViewInput


@dataclass(frozen=True)
class View:
    """One decoded view as the pipeline takes it, and where/when it was taken."""

    input: ViewInput
    frame_id: str
    stamp: Time
    source: str  # e.g. "Image rgb8" or "CompressedImage png", for log lines


class CaptureRefused(Exception):
    """A view could not be kept; the message says why (buffer full, no new image, ...)."""


class ViewBuffer:
    """Bounded list of kept views plus the latest image seen, for `auto` and `on_request` capture."""

    def __init__(self, max_views: int) -> None:
        self._lock = threading.Lock()
        self._views: list[View] = []
        self._max_views = max_views
        self._latest: View | None = None
        self._last_kept_at: float | None = None

    def __len__(self) -> int:
        with self._lock:
            return len(self._views)

    @property
    def max_views(self) -> int:
        return self._max_views

    @max_views.setter
    def max_views(self, value: int) -> None:
        """A smaller bound never drops views already kept; it only stops new ones."""
        with self._lock:
            self._max_views = value

    def observe(self, view: View) -> None:
        """Remember the newest image for an `on_request` capture."""
        with self._lock:
            self._latest = view

    def keep_if_due(self, view: View, now: float, min_interval: float) -> int | None:
        """`auto` capture: keep ``view`` when ``min_interval`` s have passed since the last kept one.

        Returns the new number of views, or None when the view was not due. Raises
        ``CaptureRefused`` when it was due but the buffer is full.
        """
        with self._lock:
            self._latest = view
            if self._last_kept_at is not None and now - self._last_kept_at < min_interval:
                return None
            count = self._append(view, now)
            self._latest = None  # a later ~/capture must not keep the same image twice
            return count

    def capture_latest(self, now: float) -> tuple[View, int]:
        """`on_request` capture: keep the newest image seen; returns it and the new number of views."""
        with self._lock:
            if self._latest is None:
                raise CaptureRefused("no new image received since the last capture")
            view = self._latest
            count = self._append(view, now)
            self._latest = None
            return view, count

    def snapshot(self) -> list[View]:
        """The kept views in capture order (a copy: the buffer may change while an estimate runs)."""
        with self._lock:
            return list(self._views)

    def clear(self) -> int:
        """Drop every view; returns how many were dropped."""
        with self._lock:
            dropped = len(self._views)
            self._views.clear()
            self._latest = None
            self._last_kept_at = None
            return dropped

    def _append(self, view: View, now: float) -> int:
        if len(self._views) >= self._max_views:
            raise CaptureRefused(f"the buffer is full ({self._max_views} views, max_views); call ~/reset first")
        self._views.append(view)
        self._last_kept_at = now
        return len(self._views)
