#!/usr/bin/env python3
"""The masks side by side: a colour image alone (GrabCut) and with aligned depth (depth + GrabCut).

Top rows: views of a fresh tabletop bag (``make_synthetic_bag --scene tabletop``, seed ``--seed``):
the image, GrabCut's mask and the depth mask, each outlined on the image, with their IoU against the
true mask. Bottom row: the official ID-Pose repository's lion photos (a figurine on a scanner bed, no
depth), with GrabCut's mask, when ``../shared/reference/idpose-official`` is beside the checkout.
Writes bench/results/tabletop/masks_before_after.png.

    python bench/mask_figure.py [--object teddy] [--views 3]
"""
from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # run as a script from a checkout

import cv2  # noqa: E402 (after the path setup)
import numpy as np  # noqa: E402

from bench.result_files import result_path  # noqa: E402
from bench.tabletop import iou, tabletop_views  # noqa: E402
from idpose_core.preprocessing import grabcut_mask  # noqa: E402
from idpose_core.segmentation import depth_cut  # noqa: E402
from idpose_ros.dataset.synthetic_bag import SyntheticBagOptions, make_bag  # noqa: E402

OUT = result_path("tabletop", "masks_before_after.png")
LION = ROOT.parent / "shared" / "reference" / "idpose-official" / "data" / "demo" / "lion"
TILE = 240


def outlined(rgb: np.ndarray, mask: np.ndarray | None, label: str) -> np.ndarray:
    """The image (TILE px high) with the mask's outline in green and a label on top."""
    image = cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR)
    if mask is not None:
        contours, _ = cv2.findContours(mask.astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
        cv2.drawContours(image, contours, -1, (0, 220, 0), max(1, image.shape[0] // 150))
    scale = TILE / image.shape[0]
    image = cv2.resize(image, (int(round(image.shape[1] * scale)), TILE), interpolation=cv2.INTER_AREA)
    cv2.rectangle(image, (0, 0), (image.shape[1], 22), (255, 255, 255), cv2.FILLED)
    cv2.putText(image, label, (4, 16), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (0, 0, 0), 1, cv2.LINE_AA)
    return image


def tabletop_rows(name: str, count: int, seed: int, work: Path) -> list[np.ndarray]:
    rows = []
    bag = make_bag(work / "bag", SyntheticBagOptions(object_name=name, views=count, seed=seed, scene="tabletop"))
    for view_id, view, truth, _ in tabletop_views(bag):
        grabcut, depth = grabcut_mask(view.rgb), depth_cut(view).mask
        rows.append(np.hstack([outlined(view.rgb, None, f"{name}, tabletop view {view_id}"),
                               outlined(view.rgb, grabcut, f"colour only (GrabCut): IoU {iou(grabcut, truth):.2f}"),
                               outlined(view.rgb, depth, f"with depth (+ GrabCut): IoU {iou(depth, truth):.2f}")]))
    return rows


def lion_row() -> np.ndarray | None:
    photos = sorted(LION.glob("*.jpg"))
    if not photos:
        return None
    tiles = []
    for photo in photos:
        rgb = cv2.cvtColor(cv2.imread(str(photo)), cv2.COLOR_BGR2RGB)
        tiles += [outlined(rgb, None, f"lion {photo.stem} (photo, no depth)"),
                  outlined(rgb, grabcut_mask(rgb), "GrabCut")]
    return np.hstack(tiles)


def stack(rows: list[np.ndarray]) -> np.ndarray:
    width = max(row.shape[1] for row in rows)
    padded = [cv2.copyMakeBorder(row, 0, 4, 0, width - row.shape[1], cv2.BORDER_CONSTANT, value=(255, 255, 255))
              for row in rows]
    return np.vstack(padded)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--object", default="teddy", help="demo object of the tabletop bag")
    parser.add_argument("--views", type=int, default=3)
    parser.add_argument("--seed", type=int, default=303)
    parser.add_argument("--out", type=Path, default=OUT)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="idpose_masks_") as folder:
        rows = tabletop_rows(args.object, args.views, args.seed, Path(folder))
    lion = lion_row()
    if lion is None:
        print(f"no lion photos at {LION}: tabletop rows only")
    else:
        rows.append(lion)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(args.out), stack(rows))
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
