"""Tables and target checks from bench/results/*.json, printed and written into bench/README.md.

Usage (from the repository root): python -m bench.report
Replaces the text between the ``<!-- results:begin -->`` and ``<!-- results:end -->`` markers of
bench/README.md; a result file that is missing shows as "not run".
"""
from __future__ import annotations

import json
from pathlib import Path

from bench.unit_costs import RESULTS, STEP_COST_FILE

README = Path(__file__).resolve().parent / "README.md"
BEGIN, END = "<!-- results:begin -->", "<!-- results:end -->"
STEP_KINDS = ("ours_step", "official_step", "ours_probe", "official_probe")


def load(name: str) -> dict | None:
    """A result file's content, or None when it has not been produced."""
    path = RESULTS / name
    return json.loads(path.read_text()) if path.is_file() else None


def minutes(seconds: float) -> str:
    return f"{seconds / 60:.0f} min" if seconds < 5940 else f"{seconds / 3600:.2f} h"


def step_cost_section(report: dict | None) -> list[str]:
    """Item 1: measured seconds and peak memory per step and probe, and the ratios."""
    if report is None:
        return ["### 1. One step and one probe, full-size model", "", "not run (`python bench/step_cost.py`)."]
    median, ratio, machine = report["median"], report["ratio_official_over_ours"], report["machine"]
    official_parts = report["runs"]["official_step"][0]["parts"]
    lines = ["### 1. One step and one probe, full-size model (random weights, float32, 256 px)", "",
             f"{machine['cpus']} CPUs, {machine['threads']} torch threads, torch {machine['torch']}, "
             f"{machine['platform']}; load average {machine['load_average_before'][0]:.1f} before, "
             f"{machine['load_average_after'][0]:.1f} after (shared machine); medians of "
             f"{report['setup']['alternations']} alternations.", "",
             "| measurement | wall s | CPU s | peak GB |", "| --- | ---: | ---: | ---: |"]
    lines += [f"| {kind} | {median[kind]['seconds']:.2f} | {median[kind]['cpu_seconds']:.2f} | "
              f"{median[kind]['peak_gb']:.2f} |" for kind in STEP_KINDS]
    lines += ["", f"Official step split (first run): " + ", ".join(f"{k} {v:.2f} s" for k, v in official_parts.items())
              + ".", "",
              f"**Per step the official path costs {ratio['step_seconds']:.2f}x our time "
              f"({ratio['step_cpu_seconds']:.2f}x CPU time) and {ratio['step_peak_gb']:.2f}x our peak memory; "
              f"per probe {ratio['probe_seconds']:.2f}x time, {ratio['probe_peak_gb']:.2f}x memory.**"]
    return lines


def counts_section(report: dict | None) -> list[str]:
    """Item 2: samples per estimate and projected full-size seconds, ours vs official."""
    if report is None:
        return ["### 2. Samples per estimate", "", "not run (`python -m bench.sample_counts`)."]
    projected = report["unit_costs"] is not None
    lines = ["### 2. Predictor samples per estimate (forward / of which backward) and projected full-size time", "",
             "| n | official | ours default | ours fast |" + (" official | ours default | ours fast |" if projected else ""),
             "| ---: | ---: | ---: | ---: |" + (" ---: | ---: | ---: |" if projected else "")]
    for row in report["rows"]:
        official, ours = row["official"], row["ours"]
        cells = [f"{official['forward_samples']} / {official['backward_samples']}"]
        cells += [f"{ours[p]['forward_samples']} / {ours[p]['backward_samples']}" for p in ("default", "fast")]
        if projected:
            cells += [minutes(official["projected_seconds"])]
            cells += [f"{minutes(ours[p]['projected_seconds'])} "
                      f"(1/{official['projected_seconds'] / ours[p]['projected_seconds']:.1f})" for p in ("default", "fast")]
        lines.append(f"| {row['n']} | " + " | ".join(cells) + " |")
    if projected:
        costs = report["unit_costs"]
        lines += ["", f"Unit costs used (s): ours step {costs['ours_step']:.2f}, ours probe of 16 "
                      f"{costs['ours_probe']:.2f}, encode per view {costs['encode_per_view']:.2f}; official step "
                      f"{costs['official_step']:.2f}, official probe {costs['official_probe']:.2f}. "
                      "(1/x) = the official time divided by ours."]
    return lines


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
    lines += ["", "Plot: [`results/oracle_schedule.png`](results/oracle_schedule.png). Fewest refinement steps "
              "within 2 points of 600: " + ", ".join(f"n={n}: {s}" for n, s in report["lean_refine_steps"].items())
              + "."]
    return lines


def end_to_end_section(report: dict | None) -> list[str]:
    """Item 4: seconds per estimate with the demo model."""
    title = "### 4. End to end with the small demo model"
    if report is None or report.get("status") != "measured":
        reason = report.get("reason", "") if report else "not run"
        return [title, "", f"**Pending**: {reason}. `python -m bench.end_to_end` measures it once the weights exist."]
    lines = [title, "", f"{report['threads']} torch threads, model loaded in {report['load_seconds']:.2f} s "
             f"(not counted below), load average {report['load_average'][0]:.1f} -> {report['load_average'][1]:.1f}.",
             "", "| n | preset | median s per estimate | scenes | RotAcc@15 | RotAcc@30 | pairs |",
             "| ---: | --- | ---: | ---: | ---: | ---: | ---: |"]
    lines += [f"| {row['n']} | {row['preset']} | {row['median_seconds']:.1f} | {len(row['runs'])} | "
              f"{row['rot_acc_15']:.0%} | {row['rot_acc_30']:.0%} | {row['pairs']} |" for row in report["rows"]]
    return lines


def targets_section(steps: dict | None, counts: dict | None, schedule: dict | None) -> list[str]:
    """The issue's targets, checked against the figures above."""
    lines = ["### Targets", "", "| target | measured | met |", "| --- | --- | --- |"]
    if steps:
        ratio = steps["ratio_official_over_ours"]["step_seconds"]
        lines.append(f"| per step >= 3x cheaper than the official path | {ratio:.2f}x | {'yes' if ratio >= 3 else 'NO'} |")
    if counts and counts["unit_costs"]:
        two = next(row for row in counts["rows"] if row["n"] == 2)
        official = two["official"]["projected_seconds"]
        for preset, bound in (("default", 5), ("fast", 20)):
            ours = two["ours"][preset]["projected_seconds"]
            lines.append(f"| n = 2 `{preset}` projected <= 1/{bound} of the official {minutes(official)} | "
                         f"{minutes(ours)} = 1/{official / ours:.1f} | {'yes' if official / ours >= bound else 'NO'} |")
    if schedule:
        for n, results in sorted(schedule["results"].items()):
            default, fast = results["steps=600"], results["fast"]
            gap = 100 * max(default[k] - fast[k] for k in ("rot_acc_15", "rot_acc_30"))
            lines.append(f"| `fast` oracle accuracy within 2 points of default, n = {n} | "
                         f"@15 {fast['rot_acc_15']:.1%} vs {default['rot_acc_15']:.1%}, "
                         f"@30 {fast['rot_acc_30']:.1%} vs {default['rot_acc_30']:.1%} | {'yes' if gap <= 2 else 'NO'} |")
    return lines


def render() -> str:
    """The whole generated block."""
    steps, counts, schedule = load(STEP_COST_FILE.name), load("sample_counts.json"), load("oracle_schedule.json")
    sections = [step_cost_section(steps), counts_section(counts), schedule_section(schedule),
                end_to_end_section(load("end_to_end.json")), targets_section(steps, counts, schedule)]
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
