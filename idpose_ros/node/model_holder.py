"""The estimator's model: loaded once per lifecycle configuration (at configure, or on first use), failure
remembered, released at cleanup.

An estimate asked for while a load runs waits for it; a load that failed is not retried until the
node is cleaned up and configured again (the model parameters are read-only) and its reason is what
``~/estimate`` and the action answer.
"""
from __future__ import annotations

import threading
from collections.abc import Callable

from idpose_core.memory import release_memory
from idpose_core.noise_predictor import NoisePredictor


class ModelUnavailable(RuntimeError):
    """The model could not be loaded; the message says why and what to download."""


class ModelHolder:
    """``get()`` the predictor; ``load`` runs at most once until ``release()``, ``on_failure(reason)`` once if
    it fails."""

    def __init__(self, load: Callable[[], NoisePredictor], on_failure: Callable[[str], None]) -> None:
        self._load = load
        self._on_failure = on_failure
        self._lock = threading.Lock()
        self._predictor: NoisePredictor | None = None
        self._problem: str | None = None
        self._loading = False

    @property
    def problem(self) -> str | None:
        """Why there is no model, or None."""
        return self._problem

    def describe(self) -> str:
        """"loaded", "loading", "not loaded" or "unavailable: <reason>", for diagnostics."""
        if self._predictor is not None:
            return "loaded"
        if self._problem is not None:
            return f"unavailable: {self._problem}"
        return "loading" if self._loading else "not loaded"

    def get(self) -> NoisePredictor:
        """The predictor, loading it now if nobody has; raises ``ModelUnavailable``."""
        with self._lock:
            if self._predictor is None and self._problem is None:
                self._loading = True
                try:
                    self._predictor = self._load()
                except Exception as exc:  # any load failure leaves the node up with a reason
                    self._problem = f"no model available: {type(exc).__name__}: {exc}"
                    self._on_failure(self._problem)
                finally:
                    self._loading = False
            if self._problem is not None:
                raise ModelUnavailable(self._problem)
            return self._predictor

    def release(self) -> bool:
        """Drop the predictor (and a remembered failure) and give its memory back; True if one was loaded.
        Waits for a load that is running."""
        with self._lock:
            loaded, self._predictor, self._problem = self._predictor is not None, None, None
        release_memory()
        return loaded
