"""The options of a training run, one field per option of ``scripts/train_demo_model.py`` (its ``--help`` says
what each does), with the same defaults."""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from idpose_core.synthetic.catalogue import CURVE_HELDOUT

DEFAULT_WORK_DIR = Path.home() / ".cache" / "idpose_demo_model"


@dataclass
class TrainingOptions:
    """What a sitting trains and how; ``out`` None means ``work_dir / "model"`` (resolved on construction)."""

    out: Path | None = None
    work_dir: Path = DEFAULT_WORK_DIR
    init_from: Path | None = None
    minutes: float = 450.0
    chunk_minutes: float = 150.0
    demo_share: float = 0.2
    toys: int = 300
    mesh_variants: int = 4
    blobs: int = 800
    catalogue_views: int = 32
    catalogue_size: int = 96
    heldout_objects: int = CURVE_HELDOUT[1]
    robot_share: float = 0.5
    robot_from: float = 0.15
    robot_ramp: float = 0.25
    lamps: int = 8
    max_steps: int = 0
    seed: int = 0
    threads: int = 2
    batch: int = 32
    lr: float = 8e-4
    ema_decay: float = 0.998
    t_min: int = 400
    t_max: int = 950
    train_views: int = 600
    heldout_views: int = 60
    image_size: int = 128
    window_jitter: float = 0.2
    gap_every: int = 100
    check_every_minutes: float = 15.0
    check_pairs: int = 24
    gap_pairs: int = 32
    pool: int = 4096
    pool_refresh: int = 8
    checkpoint_every_minutes: float = 3.0
    block_out_channels: Sequence[int] = (32, 64, 128)
    layers_per_block: int = 1
    prediction_type: str = "sample"
    film: bool = True
    token_in_timestep: bool = True
    rank_weight: float = 0.05
    rank_margin: float = 0.2
    reference_warp: bool = True

    def __post_init__(self) -> None:
        self.out = self.out or self.work_dir / "model"

    @property
    def budget_seconds(self) -> float:
        """The training budget of the whole run, over every sitting."""
        return self.minutes * 60.0

    def record(self) -> dict[str, Any]:
        """The options as training.json's phases record them (paths as strings)."""
        return {name: str(value) if isinstance(value, Path) else value for name, value in vars(self).items()}
