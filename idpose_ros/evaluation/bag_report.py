"""The evaluation report: report.json (everything), report.md (the paper's Table 1 layout), camera plots."""
from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import asdict
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402  (after choosing the non-interactive backend)
import numpy as np  # noqa: E402

from idpose_core.baselines import DEFAULT_FOV_DEG, TITLES  # noqa: E402
from idpose_core.baselines.scoring import estimate_summary  # noqa: E402
from idpose_core.evaluation.protocol import EvaluationProtocol  # noqa: E402
from idpose_core.metrics import aggregate  # noqa: E402
from idpose_ros.evaluation.bag_evaluation import BagEvaluation  # noqa: E402
from idpose_ros.evaluation.bag_views import ExtraTopics  # noqa: E402

RANDOM_METHOD = "random poses"
COLUMNS = (("rot_acc_15", "RotAcc@15° ↑", True), ("rot_acc_30", "RotAcc@30° ↑", True),
           ("pos_acc_0.2", "PosAcc@0.2 ↑", True), ("mean_rot_err_deg", "mean rot. err. (°) ↓", False),
           ("mean_pos_err", "mean pos. err. ↓", False), ("pairs", "pairs", False),
           ("distinct_pairs", "distinct pairs", False))


def model_name(model: dict[str, Any]) -> str:
    """``model_path`` as the user gave it (empty: the embedded default), or the predictor's class."""
    if "model_path" in model:
        return f"`{model['model_path']}`" if model["model_path"] else "the embedded default"
    return model.get("predictor", "unknown")


def markdown_table(methods: dict[str, dict[str, dict[str, float | int]]]) -> str:
    """Rows: each method (name -> aggregates) with each view count, then all pairs; accuracies in percent,
    as in the paper's Table 1."""
    header = "| method | views | " + " | ".join(title for _, title, _ in COLUMNS) + " |"
    rule = "|" + "---|" * (len(COLUMNS) + 2)
    rows = []
    for method, aggregates in methods.items():
        for group, summary in aggregates.items():
            cells = [f"{100.0 * summary[key]:.1f}" if percent else str(summary[key]) if key.endswith("pairs")
                     else f"{summary[key]:.3g}" for key, _, percent in COLUMNS]
            rows.append(f"| {method} | {group} | " + " | ".join(cells) + " |")
    return "\n".join([header, rule, *rows])


def summary_table(rows: dict[str, tuple[dict[str, float | int], dict[str, float | int]]], label: str = "object"
                  ) -> str:
    """One row per name (the first column headed ``label``): the model's pairs, RotAcc@15/30 and mean rotation
    error beside the random-pose baseline's RotAcc@15/30; ``rows`` maps a name to (model, random) summaries."""
    lines = [f"| {label} | pairs | RotAcc@15° | RotAcc@30° | mean rot. err. (°) | random RotAcc@15° "
             "| random RotAcc@30° |",
             "|---|---|---|---|---|---|---|"]
    for name, (model, baseline) in rows.items():
        lines.append(f"| {name} | {model['pairs']} | {100 * model['rot_acc_15']:.1f} | "
                     f"{100 * model['rot_acc_30']:.1f} | "
                     f"{model['mean_rot_err_deg']:.1f} | {100 * baseline['rot_acc_15']:.1f} | "
                     f"{100 * baseline['rot_acc_30']:.1f} |")
    return "\n".join(lines)


def convergence_table(methods: dict[str, dict[str, dict[str, float | int]]]) -> str:
    """Rows: each method (name -> ``estimate_summary``) with each view count, then all estimates: the paper's
    convergence counts "A + B of C" where the method has them, and the mean seconds per estimate."""
    rows = ["| method | views | converged: all + fewer of estimates | s / estimate |", "|---|---|---|---|"]
    for method, summaries in methods.items():
        for group, summary in summaries.items():
            counts = (f"{summary['converged']} + {summary['fewer']} of {summary['estimates']}" if "converged" in summary
                      else f"— ({summary['estimates']} estimates)")
            rows.append(f"| {method} | {group} | {counts} | {summary['mean_seconds']:.2f} |")
    return "\n".join(rows)


def intrinsics_note(evaluation: BagEvaluation) -> str:
    """Where the baselines' intrinsics came from."""
    topic = evaluation.ground_truth.inputs.camera_info_topic
    if not any("camera_info" in sources.messages for sources in evaluation.views.extras.values()):
        return f"no CameraInfo on {topic}: a {DEFAULT_FOV_DEG:g}° horizontal field of view"
    return f"the CameraInfo on {topic} nearest in time to each anchor view"


def pooled_summaries(evaluations: Sequence[BagEvaluation]) -> tuple[dict[str, float | int], dict[str, float | int]]:
    """Over several evaluations: the model's summary of all their pairs (``distinct_pairs`` tells the evaluations'
    pairs apart), and the random-pose baseline's RotAcc@15/30 and
    mean rotation error weighted by each evaluation's guesses."""
    model = aggregate([{**pair, "bag": index} for index, evaluation in enumerate(evaluations)
                       for pair in evaluation.records])["all"]
    rows = [evaluation.random_aggregates["all"] for evaluation in evaluations]
    guesses = sum(row["pairs"] for row in rows)
    random = {key: sum(row[key] * row["pairs"] for row in rows) / guesses
              for key in ("rot_acc_15", "rot_acc_30", "mean_rot_err_deg")}
    return model, {"guesses": guesses, **random}


def picks_sentence(drawn: int, protocol: EvaluationProtocol, pick_size: int, pool_size: int) -> str:
    """How many picks were evaluated, and why fewer than ``--samples`` when the pool holds fewer different pairs."""
    sentence = f"{drawn} pick{'s' if drawn != 1 else ''} of {pick_size} views (seed {protocol.seed})"
    if drawn < protocol.samples:
        sentence += (f", not the {protocol.samples} requested: {pool_size} usable views hold only {drawn} different "
                     "pairs, and no pair is scored twice")
    return sentence


def border_views(estimate: dict[str, Any]) -> list[int] | None:
    """The ids of the estimate's views whose masks touch the image border, or None when its estimator did not
    report masks (replay mode)."""
    details = estimate.get("details") or {}
    if "views" not in details:
        return None
    return [view_id for view_id, view in zip(estimate["views"], details["views"]) if view["touches_border"]]


def inputs_summary(run: BagEvaluation) -> dict[str, int]:
    """How many estimates took the anchor's polar angle from gravity and its distance from depth, how many
    views' masks each method made, how many estimates had a view whose mask touches the image border and how
    many views were unreliable (touching the border, or ambiguous)."""
    details = [estimate["details"] for estimate in run.estimates if estimate.get("details")]
    used = {"estimates": len(run.estimates),
            "polar_from_gravity": sum(d["polar_source"] == "gravity" for d in details),
            "distance_from_depth": sum(d["distance_source"] == "depth" for d in details),
            "estimates_touching_border": sum(bool(border_views(estimate)) for estimate in run.estimates),
            "views_touching_border": sum(view["touches_border"] for d in details for view in d["views"]),
            "unreliable_views": sum(not view["reliable"] for d in details for view in d["views"])}
    methods = [view["mask_method"] for d in details for view in d["views"]]
    return {**used, **{f"masks_{method}": methods.count(method) for method in sorted(set(methods))}}


def inputs_sentence(extras: ExtraTopics, used: dict[str, int]) -> str:
    """One line on the views' other inputs and what they did, for report.md."""
    topics = (("gravity", extras.gravity_topic), ("depth", extras.depth_topic),
              ("intrinsics", extras.camera_info_topic), ("masks", extras.mask_topic))
    given = [f"{kind} from {topic}" for kind, topic in topics if topic]
    masks = ", ".join(f"{key[6:]} {count}" for key, count in used.items() if key.startswith("masks_"))
    effect = (f"of {used['estimates']} estimates, {used['polar_from_gravity']} took the anchor's polar angle from "
              f"gravity and {used['distance_from_depth']} its distance from depth, and "
              f"{used['estimates_touching_border']} had a view whose object mask touches the image border "
              f"({used['views_touching_border']} views; {used['unreliable_views']} views unreliable, counting "
              "ambiguous ones)")
    return (f"Inputs: {', '.join(given) or 'the images only'}; {effect}" + (f"; masks: {masks}" if masks else "")
            + ".\n")


def plot_cameras(path: Path, true_c2w: np.ndarray, pred_c2w: np.ndarray, views: list[int], title: str) -> None:
    """True (black) and estimated (red) camera centres and viewing directions around the object, paired by dots."""
    figure = plt.figure(figsize=(6, 6))
    axes = figure.add_subplot(projection="3d")
    radius = float(np.max(np.linalg.norm(true_c2w[:, :3, 3], axis=-1)))
    for c2w, colour, label in ((true_c2w, "black", "true"), (pred_c2w, "tab:red", "estimated")):
        centres, forward = c2w[:, :3, 3], -c2w[:, :3, 2] * 0.25 * radius  # OpenGL cameras look along -z
        axes.scatter(*centres.T, color=colour, label=label, s=30)
        axes.quiver(*centres.T, *forward.T, color=colour, linewidth=1)
    for view, true_centre, pred_centre in zip(views, true_c2w[:, :3, 3], pred_c2w[:, :3, 3]):
        axes.plot(*np.stack([true_centre, pred_centre]).T, color="grey", linestyle=":", linewidth=1)
        axes.text(*true_centre, f" {view}", fontsize=8)
    axes.scatter([0], [0], [0], color="tab:blue", marker="*", s=120, label="object centre")
    axes.set(xlim=(-radius, radius), ylim=(-radius, radius), zlim=(-radius, radius), xlabel="x", ylabel="y",
             zlabel="z (up)", title=title)
    axes.set_box_aspect((1, 1, 1))
    axes.legend(loc="upper left", fontsize=8)
    figure.savefig(path, dpi=100)
    plt.close(figure)


def write_report(out: Path, evaluation: BagEvaluation) -> str:
    """Write report.json, report.md and cameras_<sample>.png into ``out``; returns the markdown table."""
    out.mkdir(parents=True, exist_ok=True)
    run, views, protocol, gt = evaluation, evaluation.views, evaluation.protocol, evaluation.ground_truth
    aggregates, random_aggregates = run.aggregates, run.random_aggregates
    estimator = run.estimator
    values, preset, mode, model = (estimator[key] for key in ("node_parameters", "solver_preset", "mode", "model"))
    method = f"ID-Pose ({values['variant']})"
    baselines = {name: {"title": TITLES.get(name, name), "pairs": run.baseline_records[name],
                        "estimates": run.baseline_estimates[name],
                        "aggregates": aggregate(run.baseline_records[name]),
                        "convergence": estimate_summary(run.baseline_estimates[name])} for name in run.baselines}
    table = markdown_table({method: aggregates, **{b["title"]: b["aggregates"] for b in baselines.values()},
                            RANDOM_METHOD: random_aggregates})
    convergence = convergence_table({method: estimate_summary(run.estimates),
                                     **{b["title"]: b["convergence"] for b in baselines.values()}})
    views_by_id = {view.view_id: view for view in views.views}
    report = {
        "bag": str(run.bag), "image_topic": gt.image_topic, "ground_truth": gt.description,
        "inputs": {**asdict(gt.extras), "used": inputs_summary(run)},
        "mode": mode, "model": model,
        "node_parameters": {"solver_preset": preset, **values},
        "protocol": {"samples": protocol.samples, "picks_drawn": len(run.picks), "seed": protocol.seed,
                     "pick_size": len(run.picks[0]),
                     "view_counts": run.view_counts, "object_center": list(gt.object_center), "up": list(gt.up),
                     "radius_unit": "relative radii in Zero-1-to-3 units: the anchor distance is 1.85"},
        "views": {"total": len(views.views), "usable": len(views.pool), "skipped": [
            {"view": view_id, "stamp": views_by_id[view_id].stamp * 1e-9, "reason": reason}
            for view_id, reason in views.skipped.items()]},
        "picks": run.picks,
        "estimates": [{**estimate, "views_touching_border": border_views(estimate)} for estimate in run.estimates],
        "pairs": run.records, "aggregates": aggregates,
        "random_baseline": {"guesses_per_pair": len(run.random_records) // max(len(run.records), 1),
                            "aggregates": random_aggregates},
        **({"baselines": baselines, "intrinsics": intrinsics_note(run)} if baselines else {}),
        **({"mask_iou": run.mask_iou} if run.mask_iou else {}),
        "failed_estimates": run.failures,
        "seconds": run.seconds,
    }
    (out / "report.json").write_text(json.dumps(report, indent=2) + "\n")
    skipped = "".join(f"- view {item['view']} ({item['stamp']:.3f} s): {item['reason']}\n"
                      for item in report["views"]["skipped"])
    failed = "".join(f"- sample {item['sample']}, views {item['views']}: {item['error']}\n" for item in run.failures)
    (out / "report.md").write_text(
        f"# Pose evaluation of `{run.bag}`\n\n"
        f"{method}, mode {mode}, model {model_name(model)}, solver preset {preset}. "
        f"{picks_sentence(len(run.picks), protocol, report['protocol']['pick_size'], len(views.pool))}, "
        f"evaluated on their first {', '.join(map(str, run.view_counts))} views; the first view is the anchor.\n"
        f"Ground truth: {report['ground_truth']}. {inputs_sentence(gt.extras, report['inputs']['used'])}"
        f"Views on {gt.image_topic}: {len(views.views)}, "
        f"usable {len(views.pool)}, skipped {len(views.skipped)}. "
        f"Estimates: {len(run.estimates)} scored, {len(run.failures)} failed.\n"
        + (f"Masks against the true masks on {run.mask_iou['true_mask_topic']}: IoU mean {run.mask_iou['mean']:.3f}, "
           f"worst {run.mask_iou['worst']:.3f} ({run.mask_iou['views']} views).\n" if run.mask_iou else "")
        + f"\n{table}\n\n"
        "Accuracies in %: rotation error below 15° / 30°, camera-centre error below 0.2 x the anchor's distance. "
        f"{RANDOM_METHOD}: each pair's target camera guessed uniformly on the sphere at the anchor's distance, "
        f"{report['random_baseline']['guesses_per_pair']} guesses per pair (its pairs column counts guesses).\n"
        + (f"\n## Baselines: convergence and time\n\n{convergence}\n\n"
           "Converged: every view placed (all), or only some (fewer: COLMAP converged only when retried with "
           "fewer views; the feature baseline placed only some pairs); a view a baseline could not place is "
           "scored as one uniform random guess. "
           f"Intrinsics: {report['intrinsics']}.\n" if baselines else "")
        + (f"\n## Skipped views\n\n{skipped}" if skipped else "")
        + (f"\n## Failed estimates (not scored)\n\n{failed}" if failed else ""))
    for sample, predicted in run.predicted_cameras.items():
        pick = run.picks[sample]
        plot_cameras(out / f"cameras_{sample}.png", run.true_cameras[sample][:len(predicted)], predicted,
                     pick[:len(predicted)], f"sample {sample}: {len(predicted)} views, anchor view {pick[0]}")
    return table
