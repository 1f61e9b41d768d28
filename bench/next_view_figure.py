#!/usr/bin/env python3
"""One ambiguous case of ``bench/next_best_view.py`` in a picture, seen from above the object: the anchor, the true
second camera, the solver's answer and runner-up for it, the suggested camera, and the second view's pose after
the suggested view was added. Azimuth is the angle, the polar angle from up the radius (the centre is straight
above). Picks the first start following the suggestion whose second view was ambiguous on two views (``--start``
picks another: docs/next_view.md shows start 6 of the committed results).
Writes bench/results/next_best_view/ambiguous_case.png.

    python bench/next_view_figure.py
"""
from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # run as a script from a checkout

import matplotlib  # noqa: E402 (after the path setup)

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from bench.result_files import result_path  # noqa: E402

RESULTS = result_path("next_best_view")
OUT = result_path("next_best_view", "ambiguous_case.png")


def ambiguous_start(loops: list[list[dict]]) -> int:
    """The first start whose second view was ambiguous on two views."""
    for index, steps in enumerate(loops):
        if steps[0]["ambiguous"][0]:
            return index
    raise SystemExit("no start had its second view ambiguous on two views")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--results", type=Path, default=RESULTS)
    parser.add_argument("--start", type=int, default=None, help="which start of the suggested policy")
    parser.add_argument("--out", type=Path, default=OUT)
    args = parser.parse_args()
    results = json.loads(args.results.read_text())
    loops, truth = results["loops"]["suggested"], results["truth_deg"]["suggested"]
    index = ambiguous_start(loops) if args.start is None else args.start
    before, after = loops[index][0], loops[index][1]
    cameras = truth[index]

    def point(polar_azimuth: list[float]) -> tuple[float, float]:
        return math.radians(polar_azimuth[1]), polar_azimuth[0]

    marks = [
        ("anchor (view 0)", cameras[0], "s", "black"),
        ("view 1, true", cameras[1], "*", "green"),
        (f"view 1, answer on 2 views ({before['errors_deg'][0]:.0f} deg off)", before["spheres_deg"][1], "o", "red"),
        ("view 1, runner-up on 2 views", before["rivals_deg"][1], "X", "orange"),
        ("suggested camera (view 2)", cameras[2], "^", "blue"),
        (f"view 1 after adding it ({after['errors_deg'][0]:.0f} deg off)", after["spheres_deg"][1], "o", "purple"),
    ]
    figure = plt.figure(figsize=(6.4, 6.0))
    axes = figure.add_subplot(projection="polar")
    for label, where, marker, colour in marks:
        if not any(math.isnan(value) for value in where):
            ring = colour == "red"  # drawn as a ring, so that an unmoved answer still shows under the later one
            axes.scatter(*point(where), marker=marker, s=340 if ring else 140, facecolors="none" if ring else colour,
                         edgecolors=colour, linewidths=2, label=label, zorder=2 if ring else 4 if marker == "X" else 3)
    axes.set_rlim(0.0, 180.0)
    axes.set_rticks([30, 60, 90, 120, 150])
    axes.set_title(f"start {index} ({results['model']}, {results['preset']}): "
                   f"{before['views']} views -> {after['views']}", fontsize=9)
    axes.legend(loc="upper center", bbox_to_anchor=(0.5, -0.06), fontsize=8, ncol=2)
    figure.tight_layout()
    args.out.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(args.out, dpi=110)
    print(f"wrote {args.out} (start {index}: view 1 {before['errors_deg'][0]:.0f} -> {after['errors_deg'][0]:.0f} "
          "deg off)")


if __name__ == "__main__":
    main()
