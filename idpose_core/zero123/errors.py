"""The one error every Zero-1-to-3 loading problem raises, with what to download."""
from __future__ import annotations

from pathlib import Path

DOWNLOAD_HINT = (
    "Get Zero-1-to-3 weights on a machine with internet, e.g. "
    "`huggingface-cli download kxic/zero123-xl --local-dir zero123-xl` (diffusers folder) or "
    "the original 105000.ckpt from https://huggingface.co/cvlab/zero123-weights, and set model_path "
    "to the folder or .ckpt (README: 'Zero-1-to-3 weights')."
)


class ModelLoadError(ValueError):
    """A model path that cannot be loaded: names the path, what is wrong and what to download."""

    def __init__(self, path: str | Path, problem: str):
        self.path = str(path)
        self.problem = problem
        super().__init__(f"{self.path}: {problem}. {DOWNLOAD_HINT}")


def summary(error: BaseException, limit: int = 400) -> str:
    """A library's error message on one line, shortened: enough to see which tensor or file is wrong."""
    text = " ".join(line.strip() for line in str(error).splitlines() if line.strip()) or type(error).__name__
    text = text.split(" You may consider adding `ignore_mismatched_sizes")[0]  # not an option for users here
    return text if len(text) <= limit else text[: limit - 3] + "..."
