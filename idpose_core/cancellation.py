"""Stopping a long computation from another thread through a ``threading.Event``.

``raise_if_cancelled`` is the check between steps. One predictor call of a full-size model can
take seconds on a CPU, so ``checked_in_modules`` also checks inside it: while active, every torch
module called on this thread checks the event before it runs, and again as its gradient flows
back, so a cancel lands within one layer of work, not one model call.
"""
from __future__ import annotations

import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

import torch
from torch.nn.modules import module as torch_module


class Cancelled(Exception):
    """The caller's cancel event was set; the computation stopped at its next check."""


def raise_if_cancelled(cancel: threading.Event | None, during: str) -> None:
    """``Cancelled`` naming ``during`` when ``cancel`` is set."""
    if cancel is not None and cancel.is_set():
        raise Cancelled(f"cancelled during {during}")


@contextmanager
def checked_in_modules(cancel: threading.Event | None, during: Callable[[], str]) -> Iterator[None]:
    """Check ``cancel`` in every torch module call (forward and backward) made on this thread meanwhile.

    ``during()`` names the work in the ``Cancelled`` message. Other threads' module calls are
    untouched. Without an event this does nothing.
    """
    if cancel is None:
        yield
        return
    owner = threading.get_ident()

    def check_gradient(gradient: torch.Tensor) -> None:
        raise_if_cancelled(cancel, during())

    def before(module: torch.nn.Module, inputs: Any) -> None:
        if threading.get_ident() == owner:
            raise_if_cancelled(cancel, during())

    def after(module: torch.nn.Module, inputs: Any, output: Any) -> None:
        if threading.get_ident() == owner and isinstance(output, torch.Tensor) and output.requires_grad:
            output.register_hook(check_gradient)

    handles = [torch_module.register_module_forward_pre_hook(before),
               torch_module.register_module_forward_hook(after)]
    try:
        yield
    finally:
        for handle in handles:
            handle.remove()
