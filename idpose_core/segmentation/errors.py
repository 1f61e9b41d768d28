"""The error the depth cut raises when depth cannot cut the object out, so a caller can fall back to the
colour methods."""
from __future__ import annotations


class DepthSegmentationError(ValueError):
    """Depth cannot cut the object out here (no intrinsics, too few readings, no plane, nothing above it)."""
