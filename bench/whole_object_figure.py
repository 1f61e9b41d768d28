#!/usr/bin/env python3
"""Figures of whole objects: the depth cut before and after on a hole onto the room and on parts behind a depth step,
and the masks' second pass across views on a part one view lost (``--figure whole_objects``); on objects standing on
a box (``--figure objects_on_boxes``).

The single-view cases are views of ``bench/mask_quality.py`` (``FIGURES``); their "before" masks come from an earlier
checkout, where this script, copied in, saves its own cut (``--save-masks FILE``: ``depth_cut``, which both
versions have). The cross-view case is a view of ``bench/mask_cross_view.py`` (``CROSS_VIEW_CASE``), before and after
its pass with the code here. Writes bench/results/mask_quality/<figure>.png.

    python bench/whole_object_figure.py --figure F --save-masks /tmp/before.npz   # in the earlier checkout
    python bench/whole_object_figure.py --figure F --before /tmp/before.npz       # here
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # run as a script from a checkout

import matplotlib  # noqa: E402 (after the path setup)

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from bench.mask_quality import challenge_view  # noqa: E402
from bench.result_files import result_path  # noqa: E402
from idpose_core.preprocessing import mask_iou  # noqa: E402
from idpose_core.segmentation import depth_cut  # noqa: E402

SEED = 31337  # the seed of the runs in docs/robot_inputs.md#whole-objects
FIGURES = {  # per figure, its cases: (title, challenge, scene index, targets, stereo)
    "whole_objects": (
        ("a mug's handle (demo, clutter 2)", "clutter", 2, "demo", False),
        ("a held-out toy, parts behind a step (clutter 0)", "clutter", 0, "heldout", False),
        ("a held-out toy before a wall (near_backdrop 0)", "near_backdrop", 0, "heldout", False),
    ),
    "objects_on_boxes": (
        ("a duck on a box (demo, on_box 0)", "on_box", 0, "demo", False),
        ("a teddy on a box, stereo (demo, on_box 1)", "on_box", 1, "demo", True),
        ("a held-out object on a box, stereo (on_box 2)", "on_box", 2, "heldout", True),
    ),
}
CROSS_VIEW_CASE = ("second pass: a part one view lost", 5151, 1, "heldout", False, 0)  # held-out scene 1, view 0


def case_views(figure: str) -> list[tuple]:
    """(title, view, true mask) of each single-view case of ``figure``."""
    found = []
    for title, challenge, index, targets, stereo in FIGURES[figure]:
        view, truth = challenge_view(challenge, index, SEED, 320, stereo=stereo, targets=targets)
        found.append((title, view, truth))
    return found


def overlay(rgb: np.ndarray, mask: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """The image dimmed, the mask's true pixels green, its false ones red, the object's missed pixels blue."""
    shown = (0.45 * rgb).astype(np.uint8)
    shown[mask & truth] = (40, 200, 60)
    shown[mask & ~truth] = (230, 40, 40)
    shown[~mask & truth] = (40, 80, 240)
    return shown


def cross_view_panels() -> tuple[str, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(title, image, mask before, mask after the pass, truth) of ``CROSS_VIEW_CASE``."""
    from bench.mask_cross_view import scene_views, second_pass

    title, seed, index, targets, stereo, k = CROSS_VIEW_CASE
    views, truth, poses = scene_views(index, seed, targets, stereo)
    found, done, _ = second_pass(views, poses)
    return title, views[k].rgb, found[k].mask, done[k].mask, truth[k]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--figure", choices=tuple(FIGURES), default="whole_objects")
    parser.add_argument("--save-masks", type=Path, help="save this checkout's masks of the cases and stop")
    parser.add_argument("--before", type=Path, help="the masks an earlier checkout saved")
    args = parser.parse_args()
    cases = case_views(args.figure)
    if args.save_masks:
        np.savez_compressed(args.save_masks, *[depth_cut(view).mask for _, view, _ in cases])
        print(args.save_masks)
        return
    if args.before is None:
        parser.error("--before is needed for the figure")
    before = np.load(args.before)
    rows = [(title, view.rgb, before[f"arr_{k}"], depth_cut(view).mask, truth)
            for k, (title, view, truth) in enumerate(cases)]
    if args.figure == "whole_objects":
        rows.append(cross_view_panels())
    figure, axes = plt.subplots(len(rows), 3, figsize=(9, 3 * len(rows)))
    for row, (title, rgb, old, new, truth) in zip(axes, rows):
        row[0].imshow(rgb)
        row[0].set_title(title, fontsize=8)
        row[1].imshow(overlay(rgb, old, truth))
        row[1].set_title(f"before: IoU {mask_iou(old, truth):.2f}", fontsize=8)
        row[2].imshow(overlay(rgb, new, truth))
        row[2].set_title(f"after: IoU {mask_iou(new, truth):.2f}", fontsize=8)
        for axis in row:
            axis.axis("off")
    figure.suptitle("green: object kept, red: not the object, blue: object missed", fontsize=9)
    figure.tight_layout()
    out = result_path("mask_quality", f"{args.figure}.png")
    figure.savefig(out, dpi=110)
    print(out)


if __name__ == "__main__":
    main()
