"""Torch devices by name, checked: "auto", "cpu", "cuda" or "cuda:N", refused with the reason when absent."""
from __future__ import annotations

import torch

DEVICE_CHOICES = ("auto", "cpu", "cuda")  # what a user picks from; ``resolve_device`` also takes "cuda:N"


class DeviceUnavailable(ValueError):
    """The requested device does not exist here; the message names it, why, and what is available."""


def available_devices() -> list[str]:
    """The devices this torch can run on here: "cpu", then "cuda:0" .. "cuda:N-1"."""
    count = torch.cuda.device_count() if torch.cuda.is_available() else 0
    return ["cpu", *(f"cuda:{index}" for index in range(count))]


def resolve_device(device: str | torch.device) -> torch.device:
    """``"auto"`` -> CUDA when available, else CPU; any other name must be a device that exists here, else
    ``DeviceUnavailable`` (e.g. "cuda" with a CPU-only torch, "cuda:3" on a one-GPU machine)."""
    if str(device) == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    available = ", ".join(available_devices())
    try:
        resolved = torch.device(device)
    except (RuntimeError, TypeError) as exc:
        raise DeviceUnavailable(f"device {str(device)!r} is not a torch device ({exc}); "
                                f"available: {available}") from None
    if resolved.type == "cpu":
        return resolved
    if resolved.type != "cuda":
        raise DeviceUnavailable(f"device {str(device)!r}: only cpu and cuda are supported; available: {available}")
    if not torch.cuda.is_available():
        why = ("this torch build has no CUDA support" if torch.version.cuda is None
               else "no CUDA device is visible (check the driver and CUDA_VISIBLE_DEVICES)")
        raise DeviceUnavailable(f"device {str(device)!r} is not available: {why} (torch {torch.__version__}); "
                                f"available: {available}")
    if resolved.index is not None and resolved.index >= torch.cuda.device_count():
        raise DeviceUnavailable(f"device {str(device)!r} is not available: only "
                                f"{torch.cuda.device_count()} CUDA device(s) are visible; available: {available}")
    return resolved
