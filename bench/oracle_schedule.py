"""Rotation accuracy on the render oracle vs refinement steps and vs probe batch, n = 2 and 4.

Every scene is solved with: the default schedule with refinement cut to 0 (exploration only), 25, 50,
100, 200, 400 and 600 (default) steps per view; the default with probe batch 4 and 8 (16 is the
default); the default with 5 adjust steps instead of 10, or 3 kept candidates instead of 5; and the
``fast`` preset. Everything else is the paper's schedule (8 x 5 candidates, 10
adjust steps, best 5 kept, triangular selection), with the oracle's learning rates
(``ORACLE_SOLVER_SETTINGS``: adjust 0.2, refine 0.02, because its error is far steeper than
Zero-1-to-3's). Reduced where it cannot change the poses: runner-up polishing off (it only sets the
ambiguity flag), 64 px input renders (the oracle answers from its own render grid), one torch thread.

Objects: 6 held-out random blobs with a marker cube and the 6 demo objects (duck, teddy, mug, soccer
ball, lego, desk; the mug and the ball are round bodies whose only azimuth cue is a small part).

Usage (from the repository root): python -m bench.oracle_schedule [--blobs 6] [--scenes 4 2]
Writes bench/results/oracle_schedule/oracle_schedule.json and oracle_schedule.png beside it.
"""
from __future__ import annotations

import argparse
import json
import time

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import torch  # noqa: E402

from bench.result_files import result_path  # noqa: E402
from bench.solver_oracle import oracle_records  # noqa: E402
from idpose_core.metrics import aggregate  # noqa: E402
from idpose_core.solver import SolverConfig  # noqa: E402
from idpose_core.synthetic.render_oracle import ORACLE_SOLVER_SETTINGS  # noqa: E402
from idpose_core.synthetic.scenes import demo_objects, oracle_objects  # noqa: E402

OUT, PLOT = result_path("oracle_schedule"), result_path("oracle_schedule", "oracle_schedule.png")

REFINE_STEPS = (0, 25, 50, 100, 200, 400, 600)
PROBE_BATCHES = (4, 8, 16)
VIEW_COUNTS = (2, 4)
ORACLE_RATES = {key: ORACLE_SOLVER_SETTINGS[key] for key in ("adjust_lr", "refine_lr")}
DEFAULT = SolverConfig.preset("default")


def sweep_configs() -> dict[str, SolverConfig]:
    """Named configs: ``steps=S`` (probe batch 16), ``batch=B`` (600 steps), two exploration cuts, ``fast``."""
    base = dict(ORACLE_RATES, runner_up_steps=0)
    configs = {f"steps={steps}": SolverConfig.preset("default", **base, refine_steps_per_view=steps)
               for steps in REFINE_STEPS}
    for batch in PROBE_BATCHES:
        if batch != DEFAULT.probe_batch:
            configs[f"batch={batch}"] = SolverConfig.preset("default", **base, probe_batch=batch)
    configs["adjust=5"] = SolverConfig.preset("default", **base, adjust_steps=5)
    configs["keep=3"] = SolverConfig.preset("default", **base, keep_top=3)
    configs["fast"] = SolverConfig.preset("fast", **base)
    return configs


def point(results: dict, count: int, name: str) -> dict:
    """Figures of one config at one view count; the default schedule answers for both sweeps."""
    if name == f"batch={DEFAULT.probe_batch}":
        name = f"steps={DEFAULT.refine_steps_per_view}"
    return results[str(count)][name]


def lean_steps(results: dict, count: int, tolerance: float = 0.02) -> int:
    """Fewest refinement steps whose RotAcc@15 and @30 are within ``tolerance`` of 600 steps'."""
    full = point(results, count, f"steps={DEFAULT.refine_steps_per_view}")
    for steps in REFINE_STEPS:
        figures = point(results, count, f"steps={steps}")
        if all(figures[key] >= full[key] - tolerance for key in ("rot_acc_15", "rot_acc_30")):
            return steps
    return DEFAULT.refine_steps_per_view


def plot(results: dict, objects: int, path) -> None:
    """Accuracy (top) and median rotation error (bottom) vs refinement steps (left) and probe batch (right)."""
    figure, axes = plt.subplots(2, 2, figsize=(10, 7), sharex="col", sharey="row")
    sweeps = ((REFINE_STEPS, "steps={}", "refinement steps per view (probe batch 16)"),
              (PROBE_BATCHES, "batch={}", "probe batch (600 refinement steps per view)"))
    for column, (values, name, label) in enumerate(sweeps):
        positions = range(len(values))  # evenly spaced categories
        for count in VIEW_COUNTS:
            figures = [point(results, count, name.format(value)) for value in values]
            for key, style in (("rot_acc_15", "-o"), ("rot_acc_30", "--s")):
                axes[0, column].plot(positions, [100 * f[key] for f in figures], style,
                                     label=f"n={count} RotAcc@{key[-2:]}")
            axes[1, column].plot(positions, [f["median_rot_err_deg"] for f in figures], "-o", label=f"n={count}")
        axes[1, column].set_xticks(list(positions), [str(value) for value in values])
        axes[1, column].set_xlabel(label)
        axes[0, column].set_ylabel("rotation accuracy (%)")
        axes[0, column].set_ylim(0, 105)
        axes[1, column].set_ylabel("median rotation error (deg)")
        axes[1, column].set_yscale("log")
        axes[0, column].legend(fontsize=8, loc="lower right")
        axes[1, column].legend(fontsize=8)
    figure.suptitle(f"ID-Pose solver on the render oracle ({objects} objects)")
    figure.tight_layout()
    figure.savefig(path, dpi=110)
    plt.close(figure)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--blobs", type=int, default=6, help="held-out oracle blobs, besides the 6 demo objects")
    parser.add_argument("--scenes", type=int, nargs=2, default=[4, 2], metavar=("N2", "N4"),
                        help="random scenes per object for n = 2 and n = 4")
    args = parser.parse_args()
    torch.set_num_threads(1)
    configs = sweep_configs()
    specs = oracle_objects(args.blobs) + demo_objects()
    results, seconds = {}, {}
    for count, scenes in zip(VIEW_COUNTS, args.scenes):
        start = time.perf_counter()
        solved = oracle_records(specs, count, configs, scenes, log_label=f"oracle sweep n={count}")
        results[str(count)] = {name: {**aggregate(found["records"])[str(count)], "ambiguous": found["ambiguous"]}
                               for name, found in solved.items()}
        seconds[str(count)] = time.perf_counter() - start
    lean = {str(count): lean_steps(results, count) for count in VIEW_COUNTS}

    print(f"\n{'config':<12}" + "".join(f"{'n=' + str(c) + ' @15':>11}{'@30':>7}{'median':>9}" for c in VIEW_COUNTS))
    for name in configs:
        cells = [results[str(c)][name] for c in VIEW_COUNTS]
        print(f"{name:<12}" + "".join(f"{f['rot_acc_15']:>11.1%}{f['rot_acc_30']:>7.1%}"
                                      f"{f['median_rot_err_deg']:>9.2g}" for f in cells))
    print("fewest refinement steps within 2 points of 600: " + ", ".join(f"n={c}: {s}" for c, s in lean.items()))

    OUT.parent.mkdir(parents=True, exist_ok=True)
    report = {
        "objects": [spec.name for spec in specs],
        "scenes_per_object": dict(zip(map(str, VIEW_COUNTS), args.scenes)),
        "configs": {name: config.as_dict() for name, config in configs.items()},
        "results": results,
        "lean_refine_steps": lean,
        "seconds": seconds,
        "reductions": "runner_up_steps 0 except fast (only sets the ambiguity flag); oracle learning rates "
                      "adjust 0.2 / refine 0.02; 64 px renders; 1 torch thread",
    }
    OUT.write_text(json.dumps(report, indent=2) + "\n")
    plot(results, len(specs), PLOT)
    print(f"wrote {OUT} and {PLOT}")


if __name__ == "__main__":
    main()
