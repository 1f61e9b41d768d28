"""Weight files read safely: their format and wholeness checked first, then tensors only.

torch.load and safetensors answer a text file, random bytes or a cut-off download with errors
such as "pop from empty list" or "header too large". Reading the first bytes and the size first
names the real problem: not a checkpoint, truncated, or a Git LFS pointer instead of the weights.
"""
from __future__ import annotations

import json
import pickle
import re
import struct
import zipfile
from pathlib import Path
from typing import Any

import torch
from safetensors.torch import load_file

from idpose_core.zero123.errors import ModelLoadError, summary

ZIP_MAGIC = b"PK\x03\x04"  # torch.save's default format is a zip archive holding <name>/data.pkl
PICKLE_PROTOCOLS = range(2, 6)  # legacy torch.save: a pickle stream that starts with PROTO (0x80) and 2..5
LFS_POINTER = b"version https://git-lfs.github.com/spec/"
SNIFF_BYTES = 512
SAFETENSORS_HEADER_LIMIT = 100_000_000  # bytes; the safetensors library refuses larger headers too


def read_weights(file: Path) -> Any:
    """What ``file`` holds (safetensors, or torch.load with weights only); any problem -> ``ModelLoadError``.

    A pickle that names any Python object besides tensors is refused, never executed.
    """
    try:
        kind = weight_file_kind(file)
    except (ValueError, OSError) as error:
        raise ModelLoadError(file, str(error)) from error
    try:
        if kind == "safetensors":
            return load_file(str(file))
        return torch.load(file, map_location="cpu", weights_only=True, mmap=kind == "zip")
    except pickle.UnpicklingError as error:
        refused = _refused_object(error)
        if not refused:
            raise ModelLoadError(file, f"damaged {kind} checkpoint: {summary(error, 300)}") from error
        raise ModelLoadError(
            file, "unsafe pickle: the checkpoint holds pickled Python objects besides tensors; unpickling them "
                  f"would execute code, which this project refuses (torch.load weights_only=True {refused})",
        ) from error
    except Exception as error:  # noqa: BLE001 - whatever the reader says, one error naming the file
        if isinstance(error, EOFError) or re.search(r"\bEOF\b|truncated", str(error)):
            raise ModelLoadError(file, f"truncated: the {kind} checkpoint ends early, as after an interrupted "
                                       "download or copy") from error
        raise ModelLoadError(file, f"not a readable {kind} checkpoint ({type(error).__name__}: "
                                   f"{summary(error, 300)})") from error


def weight_file_kind(file: Path) -> str:
    """"zip", "pickle" or "safetensors"; raises ``ValueError`` naming what is wrong with ``file`` otherwise."""
    size = file.stat().st_size
    with file.open("rb") as stream:
        head = stream.read(SNIFF_BYTES)
    if size == 0:
        raise ValueError("an empty file (0 bytes), as after an interrupted download or copy")
    if head.startswith(LFS_POINTER):
        raise ValueError("a Git LFS pointer, not the weights: run `git lfs pull` in the clone it came from, "
                         "or download the file itself")
    if head.startswith(ZIP_MAGIC):
        _check_zip(file)
        return "zip"
    if len(head) >= 2 and head[0] == 0x80 and head[1] in PICKLE_PROTOCOLS:
        return "pickle"
    if _is_safetensors_header(head, size):
        _check_safetensors(file, size)
        return "safetensors"
    if _is_text(head):
        start = head[:60].decode("utf-8", errors="replace").split("\n")[0].strip()
        raise ValueError(f"a text file, not a checkpoint (it begins {start!r}; an error page or a placeholder "
                         "saved instead of the weights)")
    raise ValueError("not a weight file: neither a PyTorch checkpoint (zip or pickle) nor safetensors "
                     f"(it begins with bytes {head[:8].hex(' ')})")


def _check_zip(file: Path) -> None:
    """A zip whose end (the central directory) is missing was cut off; one without data.pkl is no checkpoint."""
    if not zipfile.is_zipfile(file):
        raise ValueError(f"truncated or damaged: a zip archive (PyTorch's format) whose end is missing "
                         f"({file.stat().st_size} bytes), as after an interrupted download or copy")
    try:
        with zipfile.ZipFile(file) as archive:
            names = archive.namelist()
    except (zipfile.BadZipFile, OSError) as error:
        raise ValueError(f"a damaged zip archive: {error}") from error
    if not any(name == "data.pkl" or name.endswith("/data.pkl") for name in names):
        raise ValueError(f"a zip archive but not a PyTorch checkpoint (no data.pkl among {len(names)} entries)")


def _is_safetensors_header(head: bytes, size: int) -> bool:
    """safetensors: a little-endian u64 header length, then that many bytes of JSON starting with '{'."""
    if len(head) < 9:
        return False
    (length,) = struct.unpack("<Q", head[:8])
    return head[8:9] == b"{" and 0 < length <= SAFETENSORS_HEADER_LIMIT


def _check_safetensors(file: Path, size: int) -> None:
    """The JSON header must be complete and the tensors it lists must fit in the file."""
    with file.open("rb") as stream:
        (length,) = struct.unpack("<Q", stream.read(8))
        if 8 + length > size:
            raise ValueError(f"truncated: its safetensors header alone needs {8 + length} bytes, the file has {size}")
        try:
            header = json.loads(stream.read(length))
        except ValueError as error:
            raise ValueError(f"a safetensors file with a damaged header: {error}") from error
    ends = [entry["data_offsets"][1] for name, entry in header.items()
            if name != "__metadata__" and isinstance(entry, dict) and "data_offsets" in entry]
    needed = 8 + length + max(ends, default=0)
    if needed > size:
        raise ValueError(f"truncated: its header lists {needed} bytes of tensors, the file has {size} "
                         "(an interrupted download or copy)")


def _is_text(head: bytes) -> bool:
    """UTF-8 made of printable characters and whitespace (a multi-byte character may be cut at the end)."""
    text = head.decode("utf-8", errors="ignore")
    return len(text) >= len(head) - 3 and all(c.isprintable() or c in "\t\r\n" for c in text)


def _refused_object(error: pickle.UnpicklingError) -> str:
    """What the weights-only unpickler refused (e.g. ``refused argparse.Namespace``); "" for a damaged stream."""
    found = re.search(r"GLOBAL ([\w.]+)", str(error))
    if found:
        return f"refused {found.group(1)}"
    return "refused a Python object" if re.search(r"allowlisted|Can only", str(error)) else ""
