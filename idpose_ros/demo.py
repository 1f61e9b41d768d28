"""`./run demo`: the main job end to end on what ships with the package.

Evaluates every shipped demo bag (``data/demo_bags/<object>``: rendered views of one demo object
with ground-truth /tf) offline with the embedded demo model, n = 2, the `fast` solver preset (the
paper's schedule, `--preset default`, takes about twice as long), prints each bag's table, then one
summary across the demo objects beside the random-pose baseline. Extra arguments go to every
`evaluate_bag` run (e.g. `--model-path ~/models/zero123-xl` for real weights).
"""
import json
import sys
from pathlib import Path

from idpose_ros.bag_report import pooled_summaries
from idpose_ros.evaluate_bag import main as evaluate_bag

DEMO_BAGS = Path(__file__).resolve().parents[1] / "data" / "demo_bags"
DEMO_ARGS = ["--mode", "offline", "--n", "2", "--samples", "1", "--preset", "fast"]
OUT = Path("demo_output")


def demo_bags() -> list[Path]:
    """The shipped bags, one per demo object, in name order."""
    return sorted(path for path in DEMO_BAGS.iterdir() if (path / "metadata.yaml").is_file())


def summary_table(reports: dict[str, dict]) -> str:
    """One row per object and one for all pairs: RotAcc@15/30 and mean rotation error, model vs random poses."""
    lines = ["| object | pairs | RotAcc@15° | RotAcc@30° | mean rot. err. (°) | random RotAcc@15° "
             "| random RotAcc@30° |",
             "|---|---|---|---|---|---|---|"]
    rows = {name: (report["aggregates"]["all"], report["random_baseline"]["aggregates"]["all"])
            for name, report in reports.items()}
    rows["all"] = pooled_summaries(list(reports.values()))
    for name, (model, baseline) in rows.items():
        lines.append(f"| {name} | {model['pairs']} | {100 * model['rot_acc_15']:.1f} | "
                     f"{100 * model['rot_acc_30']:.1f} | "
                     f"{model['mean_rot_err_deg']:.1f} | {100 * baseline['rot_acc_15']:.1f} | "
                     f"{100 * baseline['rot_acc_30']:.1f} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    extra = sys.argv[1:] if argv is None else argv
    bags = demo_bags()
    print(f"idpose_ros demo: evaluating {len(bags)} shipped bags ({', '.join(b.name for b in bags)}) offline, "
          f"n = 2, fast preset, one estimate each; reports in ./{OUT}/<object>", flush=True)
    reports = {}
    for bag in bags:
        print(f"\n== {bag.name} ==", flush=True)
        code = evaluate_bag([str(bag), *DEMO_ARGS, "--out", str(OUT / bag.name), *extra])
        if code:
            return code
        reports[bag.name] = json.loads((OUT / bag.name / "report.json").read_text())
    print("\nAll demo objects (n = 2; random poses: each target camera guessed uniformly on the sphere):\n"
          + summary_table(reports), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
