"""Tables and target checks from bench/results/<benchmark>/*.json, printed and written into bench/README.md.

Usage (from the repository root): python -m bench.report
Replaces the text between the ``<!-- results:begin -->`` and ``<!-- results:end -->`` markers of
bench/README.md; a result file that is missing shows as "not run".
"""
from __future__ import annotations

import json
from pathlib import Path

from bench.result_files import result_path
from bench.unit_costs import QUIET_REFERENCE

README = Path(__file__).resolve().parent / "README.md"
BEGIN, END = "<!-- results:begin -->", "<!-- results:end -->"
PROJECTIONS = ("seconds", "cpu_seconds", "reference_seconds")
REPORTED_PRESETS = ("default", "fast")  # the presets whose samples and projected times the tables give


def load(benchmark: str, name: str = "") -> dict | None:
    """A result file's content (``result_path``), or None when it has not been produced."""
    path = result_path(benchmark, name)
    return json.loads(path.read_text()) if path.is_file() else None


def duration(seconds: float) -> str:
    """Minutes below 99, hours above."""
    return f"{seconds / 60:.0f} min" if seconds < 5940 else f"{seconds / 3600:.1f} h"


def step_cost_section(report: dict | None) -> list[str]:
    """Item 1: measured seconds and peak memory per step and probe, and the ratios per precision."""
    if report is None:
        return ["### 1. One step and one probe, full-size model", "", "not run (`python bench/step_cost.py`)."]
    median, machine, setup = report["median"], report["machine"], report["setup"]
    official_parts = {part: seconds for part, seconds in report["runs"]["official_step"][0]["parts"].items()
                      if part not in ("total", "cpu")}
    lines = ["### 1. One step and one probe, full-size model (random weights, 256 px)", "",
             f"{machine['cpus']} CPUs, {machine['threads']} torch threads, torch {machine['torch']}, "
             f"{machine['platform']}; load average {machine['load_average_before'][0]:.1f} before, "
             f"{machine['load_average_after'][0]:.1f} after (the run's own threads count in it); medians of "
             f"{setup['alternations']} alternations. Official: float32; ours: `kind@precision`; "
             f"ours_adjust = one solver adjust step over {setup['adjusted_candidates']} candidates in chunks of "
             f"`grad_batch` {setup['grad_batch']}.", "",
             "| measurement | wall s | CPU s | peak GB (with building) | peak GB while running | wall s per sample |",
             "| --- | ---: | ---: | ---: | ---: | ---: |"]
    for kind, figures in median.items():
        per_sample = figures.get("per_sample_seconds")
        lines.append(f"| {kind} | {figures['seconds']:.2f} | {figures['cpu_seconds']:.2f} | {figures['peak_gb']:.2f} | "
                     f"{figures['run_peak_gb']:.2f} | " + (f"{per_sample:.2f}" if per_sample else "") + " |")
    split = ", ".join(f"{k} {v:.2f} s" for k, v in official_parts.items())
    lines += ["", "Official step split (first run, wall): " + split
              + ".", ""]
    for precision, ratio in report["ratio_official_over_ours"].items():
        lines.append(f"**Ours in {precision}: per step the official path costs {ratio['step_seconds']:.2f}x our time "
                     f"({ratio['step_cpu_seconds']:.2f}x CPU time) and {ratio['step_run_peak_gb']:.2f}x our memory "
                     "while "
                     f"running ({ratio['step_peak_gb']:.2f}x the peak with building); per probe "
                     f"{ratio['probe_seconds']:.2f}x time, {ratio['probe_run_peak_gb']:.2f}x memory.**")
    return lines


def precision_section(fidelity: dict | None, accuracy: dict[str, dict | None]) -> list[str]:
    """bfloat16 against float32: the same samples on the full-size architecture, and the demo model's accuracy."""
    title = "### 1b. bfloat16 vs float32"
    if fidelity is None:
        return [title, "", "not run (`python bench/precision_fidelity.py`)."]
    figures, setup = fidelity["bfloat16_vs_float32"], fidelity["setup"]
    lines = [title, "", "Full-size architecture, random weights, identical inputs "
             f"({setup['probe_batch']} probe samples "
             f"at t = {setup['probe_t']}, {setup['steps']} single-sample steps): probe errors differ by at most "
             f"{figures['probe_error_max_relative_difference']:.1e} (relative), step errors by "
             f"{figures['step_error_max_relative_difference']:.1e}; pose gradients: cosine "
             f">= {figures['gradient_cosine_min']:.4f} (median {figures['gradient_cosine_median']:.4f}), norm ratio "
             f"{figures['gradient_norm_ratio_min']:.3f} .. {figures['gradient_norm_ratio_max']:.3f}; the best probe "
             f"sample is {'the same' if figures['probe_best_sample_same'] else 'NOT the same'}."]
    if all(accuracy.values()):
        lines += ["", "Demo model on fresh bags (`bench/demo_model_accuracy.py`, same bags and pairs in both):", "",
                  "| precision | set | pairs | RotAcc@15 | RotAcc@30 | mean rot. err. | s per estimate |",
                  "| --- | --- | ---: | ---: | ---: | ---: | ---: |"]
        for precision, report in accuracy.items():
            for name, row in report["sets"].items():
                model = row["model"]
                lines.append(f"| {precision} | {name} | {model['pairs']} | {model['rot_acc_15']:.1%} | "
                             f"{model['rot_acc_30']:.1%} | {model['mean_rot_err_deg']:.1f} deg | "
                             f"{row['seconds_per_estimate']:.1f} |")
    return lines


def counts_section(report: dict | None) -> list[str]:
    """Item 2: samples per estimate and projected full-size time, ours (per precision) vs official."""
    if report is None:
        return ["### 2. Samples per estimate", "", "not run (`python -m bench.sample_counts`)."]
    lines = ["### 2. Predictor samples per estimate and projected full-size time on this CPU", "",
             "Samples: evaluated / of which differentiated (of which batched adjust steps).", "",
             "| n | official | ours default | ours fast |", "| ---: | ---: | ---: | ---: |"]
    for row in report["rows"]:
        official, ours = row["official"], row["ours"]
        cells = [f"{official['forward_samples']} / {official['backward_samples']}"]
        cells += [f"{ours[p]['forward_samples']} / {ours[p]['backward_samples']} ({ours[p]['adjust_samples']})"
                  for p in REPORTED_PRESETS]
        lines.append(f"| {row['n']} | " + " | ".join(cells) + " |")
    costs = report["unit_costs"]
    if not costs:
        return lines
    precisions = list(costs)
    lines += ["", "Projected time: wall / CPU time from item 1's unit costs / the reference quiet-machine figures "
              "(see below); (1/x) = the official time divided by ours.", "",
              "| n | preset | official | " + " | ".join(f"ours {p}" for p in precisions) + " |",
              "| ---: | --- | ---: | " + " | ".join("---:" for _ in precisions) + " |"]
    for row in report["rows"]:
        official = " / ".join(duration(row["official"]["projected"][m]) for m in PROJECTIONS)
        for preset in REPORTED_PRESETS:
            cells = [" / ".join(f"{duration(row['ours'][preset]['projected'][p][m])} "
                                f"(1/{speedup(row, preset, p, m):.1f})"
                                for m in PROJECTIONS) for p in precisions]
            lines.append(f"| {row['n']} | {preset} | {official} | " + " | ".join(cells) + " |")
    for precision, units in costs.items():
        wall, cpu = units["seconds"], units["cpu_seconds"]
        lines += ["", f"Unit costs, ours in {precision}, wall (CPU) seconds: " + ", ".join(
            f"{label} {wall[key]:.2f} ({cpu[key]:.2f})" for label, key in (
                ("ours step", "ours_step"), ("ours adjust per sample", "ours_adjust_sample"),
                ("ours probe of 16", "ours_probe"), ("encode per view", "encode_per_view"),
                ("official step", "official_step"), ("official probe", "official_probe"))) + "."]
    reference = costs[precisions[0]]["reference_seconds"]
    quiet = ", ".join(f"{key} {value} s" for key, value in QUIET_REFERENCE.items())
    lines += ["", "Reference quiet-machine figures: " + quiet
              + "; our other units scaled from that float32 step by item 1's CPU-time ratios (e.g. "
              f"{precisions[0]} probe of 16: {reference['ours_probe']:.2f} s)."]
    return lines


def speedup(row: dict, preset: str, precision: str, measure: str) -> float:
    """Official projected time over ours for one row of sample_counts.json."""
    return row["official"]["projected"][measure] / row["ours"][preset]["projected"][precision][measure]


def schedule_section(report: dict | None) -> list[str]:
    """Item 3: oracle accuracy vs refinement steps and probe batch."""
    if report is None:
        return ["### 3. Accuracy vs schedule (render oracle)", "", "not run (`python -m bench.oracle_schedule`)."]
    counts = sorted(report["results"], key=int)
    pairs = ", ".join(f"n={n}: {next(iter(report['results'][n].values()))['pairs']} pairs" for n in counts)
    lines = ["### 3. Rotation accuracy vs schedule on the render oracle", "",
             f"{len(report['objects'])} objects ({pairs}); RotAcc@15 / RotAcc@30 / median rotation error.", "",
             "| schedule | " + " | ".join(f"n={n} @15 | n={n} @30 | n={n} median" for n in counts) + " |",
             "| --- | " + " | ".join("---: | ---: | ---:" for _ in counts) + " |"]
    for name in next(iter(report["results"].values())):
        cells = []
        for n in counts:
            figures = report["results"][n][name]
            cells += [f"{figures['rot_acc_15']:.1%}", f"{figures['rot_acc_30']:.1%}",
                      f"{figures['median_rot_err_deg']:.2g} deg"]
        label = {"steps=600": "steps=600 (default; = batch=16)"}.get(name, name)
        lines.append(f"| {label} | " + " | ".join(cells) + " |")
    plot = "results/oracle_schedule/oracle_schedule.png"
    lean = ", ".join(f"n={n}: {steps}" for n, steps in report["lean_refine_steps"].items())
    lines += ["", f"Plot: [`{plot}`]({plot}). Fewest refinement steps within 2 points of 600: {lean}."]
    return lines


def end_to_end_section(report: dict | None) -> list[str]:
    """Item 4: seconds per estimate and rotation accuracy with the demo model."""
    title = "### 4. End to end with the small demo model"
    if report is None or report.get("status") != "measured":
        return [title, "", "not run (`python -m bench.end_to_end`)."]
    lines = [title, "", f"Weights: {report['weights']}. {report['threads']} torch thread(s), model loaded in "
             f"{report['load_seconds']:.2f} s (not counted below), load average {report['load_average'][0]:.1f} -> "
             f"{report['load_average'][1]:.1f}. Each estimate: preprocessing of 256 px renders, the solver, "
             "anchor-frame poses (`estimate_view_poses`).", "",
             "| n | preset | median s per estimate | scenes | samples (differentiated) | RotAcc@15 | RotAcc@30 "
             "| pairs |",
             "| ---: | --- | ---: | ---: | ---: | ---: | ---: | ---: |"]
    for row in report["rows"]:
        first = row["runs"][0]
        cells = [str(row["n"]), row["preset"], f"{row['median_seconds']:.1f}", str(len(row["runs"])),
                 f"{first['forward_samples']} ({first['backward_samples']})",
                 f"{row['rot_acc_15']:.0%}", f"{row['rot_acc_30']:.0%}", str(row["pairs"])]
        lines.append("| " + " | ".join(cells) + " |")
    return lines


def targets_section(steps: dict | None, counts: dict | None, schedule: dict | None) -> list[str]:
    """The speed targets, checked against the figures above (yes / NO per way of costing and precision)."""
    lines = ["### Targets", "",
             "| target | ours in | this run, wall | this run, CPU time | reference quiet-machine figures |",
             "| --- | --- | --- | --- | --- |"]
    costs = counts["unit_costs"] if counts else None
    if steps and costs:
        for precision, ratio in steps["ratio_official_over_ours"].items():
            quiet = costs[precision]["reference_seconds"]
            lines.append(f"| per step >= 3x cheaper than the official path | {precision} | " + " | ".join(
                check(value, 3) for value in (ratio["step_seconds"], ratio["step_cpu_seconds"],
                                              quiet["official_step"] / quiet["ours_step"])) + " |")
    if costs:
        two = next(row for row in counts["rows"] if row["n"] == 2)
        for preset, bound in (("default", 5), ("fast", 20)):
            for precision in costs:
                lines.append(f"| n = 2 `{preset}` projected <= 1/{bound} of the official | {precision} | " + " | ".join(
                    f"{duration(two['ours'][preset]['projected'][precision][m])} vs "
                    f"{duration(two['official']['projected'][m])}: "
                    + check(speedup(two, preset, precision, m), bound, "1/")
                    for m in PROJECTIONS) + " |")
    if schedule:
        for n, results in sorted(schedule["results"].items()):
            default, fast = results["steps=600"], results["fast"]
            gap = 100 * max(default[k] - fast[k] for k in ("rot_acc_15", "rot_acc_30"))
            lines.append(f"| `fast` oracle rotation accuracy within 2 points of default, n = {n} | (any) | "
                         f"@15 {fast['rot_acc_15']:.1%} vs {default['rot_acc_15']:.1%}, @30 {fast['rot_acc_30']:.1%} "
                         f"vs {default['rot_acc_30']:.1%}: {'yes' if gap <= 2 else 'NO'} | (same) | (same) |")
    return lines


def check(value: float, bound: float, prefix: str = "") -> str:
    """``value`` against a lower ``bound``, e.g. "1/7.1 yes" or "1.82x NO"."""
    shown = f"{prefix}{value:.1f}" if prefix else f"{value:.2f}x"
    return f"{shown} {'yes' if value >= bound else 'NO'}"


def closing_note(steps: dict | None, counts: dict | None, schedule: dict | None, end_to_end: dict | None) -> list[str]:
    """The headline ratios in one paragraph per precision."""
    if not (steps and counts and counts["unit_costs"] and schedule):
        return ["### Summary", "", "Incomplete: run `python bench/run_all.py`."]
    two = next(row for row in counts["rows"] if row["n"] == 2)
    fast = {n: results["fast"]["rot_acc_15"] for n, results in schedule["results"].items()}
    default = {n: results["steps=600"]["rot_acc_15"] for n, results in schedule["results"].items()}
    parts = [f"Measured with a 1-minute load average of {steps['machine']['load_average_before'][0]:.1f} before the "
             f"run on {steps['machine']['cpus']} cores; the official path in float32."]
    for precision, ratio in steps["ratio_official_over_ours"].items():
        def projected(preset: str, measure: str, precision: str = precision) -> float:
            return speedup(two, preset, precision, measure)

        parts.append(
            f"Ours in {precision}: per step the official path costs {ratio['step_seconds']:.2f}x our wall time "
            f"({ratio['step_cpu_seconds']:.2f}x CPU time) and {ratio['step_run_peak_gb']:.2f}x our memory; a two-view "
            "estimate with the paper's schedule is projected at "
            f"1/{projected('default', 'seconds'):.1f} of the official "
            f"time (1/{projected('default', 'cpu_seconds'):.1f} from CPU times, "
            f"1/{projected('default', 'reference_seconds'):.1f} from the quiet-machine figures), the `fast` preset at "
            f"1/{projected('fast', 'seconds'):.1f} (1/{projected('fast', 'cpu_seconds'):.1f}, "
            f"1/{projected('fast', 'reference_seconds'):.1f}).")
    parts.append("`fast` keeps oracle RotAcc@15 " + ", ".join(
        f"{fast[n]:.0%} vs {default[n]:.0%} (n = {n})" for n in sorted(fast)) + ".")
    if end_to_end and end_to_end.get("status") == "measured":
        parts.append("End to end, the demo model takes " + ", ".join(
            f"{row['median_seconds']:.0f} s (n = {row['n']}, {row['preset']})" for row in end_to_end["rows"])
                     + " per estimate on one thread.")
    return ["### Summary", "", " ".join(parts)]


def render() -> str:
    """The whole generated block."""
    steps, counts, schedule = load("step_cost"), load("sample_counts"), load("oracle_schedule")
    end_to_end = load("end_to_end")
    accuracy = {precision: load("demo_model_accuracy", f"demo_model_accuracy{suffix}.json")
                for precision, suffix in (("float32", ""), ("bfloat16", "_bfloat16"))}
    sections = [step_cost_section(steps), precision_section(load("precision_fidelity"), accuracy),
                counts_section(counts), schedule_section(schedule),
                end_to_end_section(end_to_end), targets_section(steps, counts, schedule),
                closing_note(steps, counts, schedule, end_to_end)]
    return "\n\n".join("\n".join(section) for section in sections)


def main() -> None:
    block = render()
    print(block)
    text = README.read_text()
    if BEGIN not in text or END not in text:
        raise SystemExit(f"{README} lacks the {BEGIN} / {END} markers")
    head, rest = text.split(BEGIN, 1)
    README.write_text(f"{head}{BEGIN}\n{block}\n{END}{rest.split(END, 1)[1]}")
    print(f"\nupdated {README}")


if __name__ == "__main__":
    main()
