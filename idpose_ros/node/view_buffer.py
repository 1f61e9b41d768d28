"""The estimator's view buffer: decoded views kept in capture order (the first one the anchor) and the latest image.

Thread-safe, because image callbacks, services and the estimation worker all touch it.
"""
from __future__ import annotations

import threading
from collections.abc import Callable
from dataclasses import dataclass
from enum import StrEnum

from builtin_interfaces.msg import Time

from idpose_core.pipeline import ViewInput
from idpose_ros.node.raw_image import RawImage
from idpose_ros.view_decoding import ViewMessages


@dataclass(frozen=True)
class View:
    """One decoded view as the pipeline takes it, and where/when it was taken."""

    input: ViewInput
    frame_id: str
    stamp: Time
    source: str  # e.g. "Image rgb8" or "CompressedImage png", for log lines
    pending: frozenset[str] = frozenset()  # inputs whose message had not arrived when the view was kept
    received: ViewMessages | None = None  # the messages it was made from, kept while the node records


class CaptureMode(StrEnum):
    """How images become views (the ``capture_mode`` parameter's choices)."""

    AUTO = "auto"  # the image that arrives min_view_interval s after the last kept view
    ON_REQUEST = "on_request"  # the latest image, on ~/capture


class CaptureRefused(Exception):
    """A view could not be kept; the message says why (buffer full, no new image, ...)."""


class ImageRefused(CaptureRefused):
    """The image itself cannot be a view (unreadable, too large, implausible); the message names it and why."""


class ViewBuffer:
    """Bounded list of kept views plus the latest image message seen, not decoded yet.

    Both capture modes keep a view the same way, ``keep_latest``: the latest message is handed out
    once, decoded and checked, and kept. ``auto`` asks ``due`` first; ``on_request`` does it on ``~/capture``.
    """

    def __init__(self, max_views: int) -> None:
        self._lock = threading.Lock()
        self._views: list[View] = []
        self._max_views = max_views
        self._latest: RawImage | None = None
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

    def observe(self, image: RawImage) -> None:
        """Remember the newest image message (the previous one is dropped undecoded)."""
        with self._lock:
            self._latest = image

    def due(self, now: float, min_interval: float) -> bool:
        """`auto` capture: whether ``min_interval`` s have passed since the last kept view."""
        with self._lock:
            return self._last_kept_at is None or now - self._last_kept_at >= min_interval

    def _take_latest(self) -> RawImage:
        """The newest image message, handed out once; ``CaptureRefused`` when the buffer is full or none came."""
        with self._lock:
            self._check_room()
            if self._latest is None:
                raise CaptureRefused("no new image received since the last capture")
            image, self._latest = self._latest, None
            return image

    def _keep(self, view: View, now: float) -> int:
        """Append a decoded view; returns the new number of views (``CaptureRefused`` when full)."""
        with self._lock:
            self._check_room()
            self._views.append(view)
            self._last_kept_at = now
            return len(self._views)

    def keep_latest(self, prepare: Callable[[RawImage], View], now: float) -> tuple[View, int]:
        """Take the newest message, ``prepare`` it into a view (decode and check; it raises ``ImageRefused``
        for an image that cannot be one) and keep it; returns the view and the new number of views."""
        view = prepare(self._take_latest())
        return view, self._keep(view, now)

    def restore(self, views: list[View]) -> None:
        """Views resumed from a recording, in capture order, in place of an empty buffer (a bound lowered since
        does not drop them)."""
        with self._lock:
            self._views = list(views)

    def complete(self, kind: str, fill: Callable[[View], View | None]) -> int:
        """Give views still waiting for ``kind`` (depth, mask) what ``fill`` makes of them (None: not this one);
        returns how many were filled."""
        with self._lock:
            filled = 0
            for index, view in enumerate(self._views):
                if kind in view.pending and (done := fill(view)) is not None:
                    self._views[index] = done
                    filled += 1
            return filled

    def anchor(self) -> View | None:
        """The first kept view, None while the buffer is empty."""
        with self._lock:
            return self._views[0] if self._views else None

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

    def _check_room(self) -> None:
        if len(self._views) >= self._max_views:
            raise CaptureRefused(f"the buffer is full ({self._max_views} views, max_views); call ~/reset first")
