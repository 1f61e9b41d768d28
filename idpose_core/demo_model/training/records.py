"""What a model folder records beside its weights: the solver's defaults for it and ``training.json`` (the
lineage's options, data, schedule and final checks)."""
from __future__ import annotations

import json
from dataclasses import asdict
from pathlib import Path

from idpose_core.demo_model.config import DemoModelConfig
from idpose_core.demo_model.training.checks import CHECK_AZIMUTHS, CHECK_POLARS_DEG
from idpose_core.demo_model.training.data import TrainingData
from idpose_core.demo_model.training.options import TrainingOptions
from idpose_core.demo_model.training_data import RobotCrops
from idpose_core.synthetic.scenes import CAMERA_POLAR_DEG, FOV_DEG

TRAINING_SCRIPT = "scripts/train_demo_model.py"


def write_solver_defaults(folder: Path, probe_step: int, t_max: int, config: DemoModelConfig) -> None:
    """``solver_defaults.json``: probe and refine at the timestep of the largest loss gap; the annealed starts run
    from the largest training timestep down to it."""
    probe_t = probe_step / config.num_train_timesteps
    (folder / "solver_defaults.json").write_text(json.dumps(
        {"probe_t": probe_t, "refine_t_range": [probe_t, (probe_step + 10) / config.num_train_timesteps],
         "start_t_range": [max(t_max / config.num_train_timesteps, probe_t), probe_t]},
        indent=2) + "\n")


def write_training_record(folder: Path, options: TrainingOptions, config: DemoModelConfig, data: TrainingData,
                          history: list[dict], step: int, elapsed: float, gaps: dict[str, dict[int, float]],
                          probe_step: int, final: dict[str, dict[str, float]], check_pairs: int) -> None:
    """``training.json``: every sitting's options (``history``), the architecture, the robot crops and the data,
    how far the run got in ``step``s and ``elapsed`` seconds, and the final loss gaps and inversion checks."""
    (folder / "training.json").write_text(json.dumps({
        "script": TRAINING_SCRIPT,
        "seed": options.seed,
        "phases": history,
        "config": asdict(config),
        "robot_crops": {"share": options.robot_share, "from": options.robot_from, "ramp": options.robot_ramp,
                        "lamps_per_demo_object": options.lamps, "lamps_per_catalogue_object": 1,
                        "reference": asdict(RobotCrops.reference), "target": asdict(RobotCrops.target)},
        "data": {"objects": data.names(), "demo_share": options.demo_share,
                 "demo_views_per_object": data.demo.views_per_object,
                 "catalogue_views_per_object": data.catalogue.views_per_object,
                 "heldout_views_per_object": data.novel.views_per_object, "polar_deg": list(CAMERA_POLAR_DEG),
                 "fov_deg": FOV_DEG},
        "steps": step, "batch": options.batch, "wall_minutes": round(elapsed / 60, 1),
        "budget_minutes": options.minutes, "finished": elapsed >= options.budget_seconds, "threads": options.threads,
        "loss_gap_by_t": gaps,
        "final_check": {"t": probe_step, **final, "pairs": check_pairs,
                        "grid": f"{CHECK_AZIMUTHS} azimuths x polar offsets {CHECK_POLARS_DEG}"},
    }, indent=2) + "\n")
