"""Training of the demo model on pybullet renders of many objects, in resumable sittings; the library behind
``scripts/train_demo_model.py``."""
from idpose_core.demo_model.training.loop import train
from idpose_core.demo_model.training.options import TrainingOptions

__all__ = ["TrainingOptions", "train"]
