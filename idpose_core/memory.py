"""Giving a released model's memory back: to the CUDA driver, and from the C heap to the system."""
from __future__ import annotations

import ctypes
import ctypes.util
import gc

import torch


def release_memory() -> None:
    """Collect garbage, empty torch's CUDA cache (when CUDA was used) and trim glibc's heap, so that the
    memory of a model just dropped shows up as freed in the process's RSS and on the GPU."""
    gc.collect()
    if torch.cuda.is_initialized():
        torch.cuda.empty_cache()
    libc = ctypes.util.find_library("c")
    if libc:
        trim = getattr(ctypes.CDLL(libc), "malloc_trim", None)
        if trim is not None:  # glibc only
            trim(0)
