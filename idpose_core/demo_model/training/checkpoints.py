"""The model a run trains and its state: the architecture the options ask for, the EMA predictor, and the
checkpoint a sitting saves and the next one resumes from."""
from __future__ import annotations

import json
from pathlib import Path

import torch
from diffusers.training_utils import EMAModel

from idpose_core.demo_model.config import DemoModelConfig
from idpose_core.demo_model.demo_predictor import DemoPredictor
from idpose_core.demo_model.model import DemoDiffusionModel
from idpose_core.demo_model.training.options import TrainingOptions

CHECKPOINT_FILE = "checkpoint.pt"


def model_config(options: TrainingOptions) -> DemoModelConfig:
    """The architecture the options ask for: relative poses only (no absolute view head)."""
    return DemoModelConfig(block_out_channels=tuple(options.block_out_channels),
                           layers_per_block=options.layers_per_block,
                           resnet_time_scale_shift="scale_shift" if options.film else "default",
                           token_in_timestep_embedding=options.token_in_timestep,
                           prediction_type=options.prediction_type, absolute_view_conditioning=False,
                           reference_warp=options.reference_warp)


def ema_predictor(model: DemoDiffusionModel, ema: EMAModel, config: DemoModelConfig) -> DemoPredictor:
    """A frozen copy of the model carrying the EMA weights."""
    copy = DemoDiffusionModel(config)
    copy.load_state_dict(model.state_dict())
    ema.copy_to(copy.parameters())
    return DemoPredictor(copy)


def restore(options: TrainingOptions, model: DemoDiffusionModel, optimizer: torch.optim.Optimizer, ema: EMAModel
            ) -> tuple[int, float, list[dict]]:
    """(step, training seconds, history) to go on from: the work dir's checkpoint (exactly), else ``init_from``'s
    model folder (its weights as model and EMA, a fresh optimizer), else a fresh start."""
    checkpoint_path = options.work_dir / CHECKPOINT_FILE
    if checkpoint_path.is_file():
        state = torch.load(checkpoint_path, weights_only=True)
        model.load_state_dict(state["model"])
        optimizer.load_state_dict(state["optimizer"])
        ema.load_state_dict(state["ema"])
        print(f"resumed from {checkpoint_path} at step {state['step']} ({state['elapsed'] / 60:.1f} min)")
        return int(state["step"]), float(state["elapsed"]), json.loads(state["history"])
    if options.init_from is not None:
        records = json.loads((options.init_from / "training.json").read_text())
        model.load_state_dict(DemoDiffusionModel.from_pretrained(options.init_from).state_dict())
        ema.load_state_dict({**ema.state_dict(), "shadow_params": [p.detach().clone() for p in model.parameters()]})
        print(f"initialised from {options.init_from} at step {records['steps']} ({records['wall_minutes']:.1f} min)")
        return int(records["steps"]), 60.0 * float(records["wall_minutes"]), records["phases"]
    return 0, 0.0, []


def save_checkpoint(path: Path, model: DemoDiffusionModel, optimizer: torch.optim.Optimizer, ema: EMAModel,
                    step: int, elapsed: float, history: list[dict]) -> None:
    """Atomically write everything needed to resume (``history``: the options of every start and resume)."""
    temporary = path.with_suffix(".tmp")
    torch.save({"model": model.state_dict(), "optimizer": optimizer.state_dict(), "ema": ema.state_dict(),
                "step": step, "elapsed": elapsed, "history": json.dumps(history)}, temporary)
    temporary.replace(path)
