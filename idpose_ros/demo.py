"""`./run demo`: the main job end to end on what ships with the package.

Evaluates the shipped demo bag (rendered views of a demo object with ground-truth /tf) offline,
n = 2, and prints the paper's table. The model is the embedded default when its weights ship;
until they do, a tiny Zero-1-to-3 with RANDOM weights runs the same code path, and the demo says
so: its poses show that the pipeline runs, not how accurate it is. Extra arguments go to
`evaluate_bag` (e.g. `--model-path ~/models/zero123-xl` for real weights).
"""
import sys
import tempfile
from pathlib import Path

from idpose_core.demo_model.model import WEIGHTS_FILE
from idpose_core.demo_model.predictor import EMBEDDED_MODEL_DIR
from idpose_core.zero123 import Zero123Predictor
from idpose_ros.evaluate_bag import main as evaluate_bag

DEMO_BAG = Path(__file__).resolve().parents[1] / "data" / "demo_bag"
DEMO_ARGS = ["--mode", "offline", "--n", "2", "--samples", "1", "--out", "demo_output"]
RANDOM_MODEL_ARGS = ["--preset", "fast", "--image-size", "64"]


def main(argv: list[str] | None = None) -> int:
    extra = sys.argv[1:] if argv is None else argv
    args = [str(DEMO_BAG), *DEMO_ARGS]
    print(f"idpose_ros demo: evaluating {DEMO_BAG} (offline, n = 2); report in ./demo_output", flush=True)
    if (EMBEDDED_MODEL_DIR / WEIGHTS_FILE).is_file() or "--model-path" in extra:
        return evaluate_bag([*args, *extra])
    print("idpose_ros demo: NO trained embedded model ships yet, so this run uses a tiny Zero-1-to-3 with "
          "RANDOM weights (the real code path, meaningless poses). For real poses pass "
          "--model-path <Zero-1-to-3 folder or .ckpt> (README: Zero-1-to-3 weights).", flush=True)
    with tempfile.TemporaryDirectory(prefix="idpose_demo_model_") as folder:
        Zero123Predictor.tiny(seed=0).save_pretrained(folder)
        return evaluate_bag([*args, "--model-path", folder, *RANDOM_MODEL_ARGS, *extra])


if __name__ == "__main__":
    sys.exit(main())
