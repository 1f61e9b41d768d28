"""`make_synthetic_bag OUT`: render pybullet views of an object from random cameras into a real rosbag2.

A thin front end over ``idpose_ros.dataset.synthetic_bag`` (its docstring lists the topics written).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from idpose_ros.dataset.synthetic_bag import LIGHTS, OBJECT_SETS, SCENES, TABLETOP_SIZE, SyntheticBagOptions, make_bag
from idpose_ros.evaluation.bag_io import BagError


def parse_args(argv: list[str] | None) -> tuple[argparse.Namespace, SyntheticBagOptions]:
    default = SyntheticBagOptions()
    parser = argparse.ArgumentParser(prog="make_synthetic_bag", description=__doc__.split("\n\n")[0].split(": ", 1)[1])
    parser.add_argument("out", type=Path, help="bag folder to create (must not exist)")
    parser.add_argument("--storage", choices=("sqlite3", "mcap"), default=default.storage)
    parser.add_argument("--objects", choices=tuple(OBJECT_SETS), default=default.object_set, help="object set")
    parser.add_argument("--object", default=default.object_name, help="object name in the set (default: the first)")
    parser.add_argument("--views", type=int, default=default.views, help=f"number of views (default {default.views})")
    parser.add_argument("--seed", type=int, default=default.seed, help="seed of the cameras, rolls and scene")
    parser.add_argument("--size", type=int, default=default.size,
                        help=f"image width and height in pixels (default 256, tabletop {TABLETOP_SIZE})")
    parser.add_argument("--scene", choices=SCENES, default=default.scene,
                        help="plain: the object alone on white (alpha = mask); tabletop: on a table among others, "
                             "with depth")
    parser.add_argument("--roll-deg", type=float, default=default.roll_deg,
                        help="turn each camera about its optical axis by a random angle in [-R, R] degrees")
    parser.add_argument("--depth-format", choices=("16UC1", "32FC1"), default=default.depth_format,
                        help="tabletop depth encoding: 16UC1 millimetres (RealSense) or 32FC1 metres")
    parser.add_argument("--light", choices=LIGHTS, default=default.light,
                        help="tabletop: a random lamp with shadows, or the light of the white scenes (training)")
    args = parser.parse_args(argv)
    options = SyntheticBagOptions(args.storage, args.objects, args.object, args.views, args.seed, args.size,
                                  args.scene, args.roll_deg, args.depth_format, args.light)
    try:
        options.check()
    except BagError as err:
        parser.error(str(err))
    return args, options


def main(argv: list[str] | None = None) -> int:
    args, options = parse_args(argv)
    try:
        out = make_bag(args.out, options)
    except BagError as err:
        print(f"make_synthetic_bag: {err}", file=sys.stderr)
        return 2
    print(f"wrote {out} ({options.storage}, {options.views} views, {options.scene} scene)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
