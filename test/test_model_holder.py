"""The node's model holder: one load per configuration, a failure remembered with its reason, a load that runs
waited for, everything dropped at release."""
from __future__ import annotations

import threading

import pytest

from idpose_core.zero123 import Zero123Predictor
from idpose_ros.node.model_holder import ModelHolder, ModelUnavailable


class CountingLoad:
    """Loads the tiny random Zero-1-to-3 and counts its calls; ``fail`` makes a load raise instead."""

    def __init__(self, fail: bool = False, gate: threading.Event | None = None) -> None:
        self.calls, self.fail, self.gate = 0, fail, gate
        self.started = threading.Event()

    def __call__(self) -> Zero123Predictor:
        self.calls += 1
        self.started.set()
        if self.gate is not None:
            self.gate.wait()
        if self.fail:
            raise FileNotFoundError("no weights at /nowhere")
        return Zero123Predictor.tiny(seed=0)


def test_the_model_loads_once_and_is_released():
    load, failures = CountingLoad(), []
    holder = ModelHolder(load, failures.append)
    assert holder.describe() == "not loaded" and holder.problem is None
    first = holder.get()
    assert holder.get() is first and load.calls == 1 and holder.describe() == "loaded"
    assert holder.release() is True and holder.describe() == "not loaded"
    assert holder.release() is False, "nothing left to release"
    assert holder.get() is not first and load.calls == 2, "configured again: loaded again"
    assert failures == []


def test_a_failed_load_is_remembered_with_its_reason_until_release():
    load, failures = CountingLoad(fail=True), []
    holder = ModelHolder(load, failures.append)
    for _ in range(2):
        with pytest.raises(ModelUnavailable, match="FileNotFoundError: no weights at /nowhere"):
            holder.get()
    assert load.calls == 1, "not retried before a release"
    assert failures == [holder.problem] and holder.describe() == f"unavailable: {holder.problem}"
    holder.release()
    assert holder.problem is None and holder.describe() == "not loaded"
    load.fail = False
    assert holder.get() is not None and load.calls == 2


def test_a_second_caller_waits_for_the_load_that_runs():
    gate = threading.Event()
    load = CountingLoad(gate=gate)
    holder = ModelHolder(load, lambda reason: None)
    got: list[Zero123Predictor] = []
    first = threading.Thread(target=lambda: got.append(holder.get()))
    first.start()
    assert load.started.wait(10.0)
    assert holder.describe() == "loading"
    second = threading.Thread(target=lambda: got.append(holder.get()))
    second.start()
    gate.set()
    first.join(10.0)
    second.join(10.0)
    assert len(got) == 2 and got[0] is got[1] and load.calls == 1
