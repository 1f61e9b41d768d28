"""Cancellation inside a model call: each torch module checks the event, forward and backward, on its thread only."""
import threading

import pytest
import torch

from idpose_core.cancellation import Cancelled, checked_in_modules, raise_if_cancelled

LAYERS = 40


class Layer(torch.nn.Module):
    """A linear layer that records its forward calls, and sets ``cancel`` when it is the ``trigger``-th."""

    def __init__(self, log: list[str], cancel: threading.Event, trigger: int | None) -> None:
        super().__init__()
        self.linear = torch.nn.Linear(4, 4)
        self.log, self.cancel, self.trigger = log, cancel, trigger

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        self.log.append("forward")
        if len(self.log) == self.trigger:
            self.cancel.set()
        return self.linear(x)


def stack(cancel: threading.Event, trigger: int | None = None) -> tuple[torch.nn.Module, list[str]]:
    log: list[str] = []
    return torch.nn.Sequential(*[Layer(log, cancel, trigger) for _ in range(LAYERS)]), log


def test_a_cancel_during_the_forward_pass_stops_at_the_next_module():
    cancel = threading.Event()
    model, log = stack(cancel, trigger=5)
    with pytest.raises(Cancelled, match="cancelled during the test's model call"), \
            checked_in_modules(cancel, lambda: "the test's model call"):
        model(torch.ones(2, 4))
    assert len(log) == 5, "no module may run after the one that saw the cancel"


def test_a_cancel_during_the_backward_pass_stops_it():
    cancel = threading.Event()
    model, _ = stack(cancel)
    reached = []
    x = torch.ones(2, 4, requires_grad=True)
    with checked_in_modules(cancel, lambda: "backward"):
        output = model(x).sum()
        hooks = [layer.linear.weight.register_hook(lambda grad, i=i: reached.append(i) or cancel.set())
                 for i, layer in enumerate(model)]
        with pytest.raises(Cancelled):
            output.backward()
    for hook in hooks:
        hook.remove()
    assert len(reached) < 3 and x.grad is None, "the gradient never reached the input"


def test_other_threads_and_later_calls_are_untouched():
    cancel = threading.Event()
    cancel.set()
    model, log = stack(threading.Event())
    results = []
    with checked_in_modules(cancel, lambda: "elsewhere"):
        worker = threading.Thread(target=lambda: results.append(model(torch.ones(1, 4))))
        worker.start()
        worker.join()
    assert len(results) == 1 and len(log) == LAYERS
    model(torch.ones(1, 4))  # the scope is over: no check any more
    with checked_in_modules(None, lambda: "no event"):
        model(torch.ones(1, 4))
    with pytest.raises(Cancelled, match="cancelled during setup"):
        raise_if_cancelled(cancel, "setup")
