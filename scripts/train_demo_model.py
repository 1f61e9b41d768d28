#!/usr/bin/env python3
"""Train the embedded model on pybullet renders of many objects, on the CPU, in resumable chunks.

Renders its own data (cached as .npz in --work-dir): the six demo objects from many cameras, and the training
catalogue (``idpose_core.synthetic.catalogue``: ``random_urdfs`` blobs 000-799, composed toys, recoloured
``pybullet_data`` meshes) from fewer cameras each. Trains the small view-conditioned diffusion model on view
pairs of one object with their relative pose (no absolute view: the model must read the pose from the pair, so it
works on objects it never saw), with an EMA of its weights and a cosine learning rate over the whole ``--minutes``
budget. One sitting trains at most ``--chunk-minutes`` and ends with a checkpoint and the model folder; rerun the
same command to go on (from the checkpoint in --work-dir, or, on another machine, from a model folder given by
``--init-from``). Logs the true-vs-wrong-pose loss gap and a grid-search inversion check on held-out objects
(``random_urdfs`` 800-899 and held-out toys; 900-999 are never used) and on held-out cameras of the demo objects to
``curve.csv`` against training minutes; the model folder carries the whole lineage's curve (CSV and PNG), so a
sitting started with ``--init-from`` goes on with it.

A growing share of the pairs are a robot's crops: the cameras rendered again under random lamps with shadows, in a
camera's tone, the reference augmented by ``idpose_core.demo_model.robot_crops``. The share is 0 while the model
first learns to read the pose (``--robot-from`` of the budget), then grows linearly to ``--robot-share`` over
``--robot-ramp`` of the budget.

    python scripts/train_demo_model.py --out DIR    # a sitting of at most 150 min; rerun it for the next one
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # run as a script from a checkout

from idpose_core.demo_model.training import TrainingOptions, train


def parse_args() -> argparse.Namespace:
    defaults = TrainingOptions()
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", type=Path, help="where the model folder goes (default: WORK_DIR/model)")
    parser.add_argument("--work-dir", type=Path, default=defaults.work_dir,
                        help="render cache, checkpoint and curve.csv (not in git)")
    parser.add_argument("--init-from", type=Path,
                        help="a model folder this script wrote (with training.json): go on from its weights, steps and "
                             "minutes when WORK_DIR holds no checkpoint (another machine, or a fresh cache)")
    parser.add_argument("--minutes", type=float, default=defaults.minutes,
                        help="training budget of the whole run, over every sitting: the learning rate and the robot "
                             "crops' share follow it")
    parser.add_argument("--chunk-minutes", type=float, default=defaults.chunk_minutes,
                        help="most training minutes of this sitting; rendering the data takes about 5 more")
    parser.add_argument("--demo-share", type=float, default=defaults.demo_share,
                        help="share of the pairs of the six demo objects")
    parser.add_argument("--toys", type=int, default=defaults.toys, help="composed toys in the training catalogue")
    parser.add_argument("--mesh-variants", type=int, default=defaults.mesh_variants,
                        help="variants of every pybullet_data mesh")
    parser.add_argument("--blobs", type=int, default=defaults.blobs, help="training blobs (random_urdfs 000..)")
    parser.add_argument("--catalogue-views", type=int, default=defaults.catalogue_views,
                        help="cameras per catalogue object")
    parser.add_argument("--catalogue-size", type=int, default=defaults.catalogue_size,
                        help="render size of the catalogue objects")
    parser.add_argument("--heldout-objects", type=int, default=defaults.heldout_objects,
                        help="held-out blobs (random_urdfs 800..) and as many held-out toys the curve follows")
    parser.add_argument("--robot-share", type=float, default=defaults.robot_share,
                        help="share of the pairs that are robot crops")
    parser.add_argument("--robot-from", type=float, default=defaults.robot_from,
                        help="share of the budget trained on clean renders only, before robot crops come in")
    parser.add_argument("--robot-ramp", type=float, default=defaults.robot_ramp,
                        help="share of the budget over which the robot crops' share grows to --robot-share")
    parser.add_argument("--lamps", type=int, default=defaults.lamps,
                        help="random lamps per demo object its cameras are rendered under "
                             "(catalogue objects: one each)")
    parser.add_argument("--max-steps", type=int, default=defaults.max_steps,
                        help="stop after this many steps (0: budget only)")
    parser.add_argument("--seed", type=int, default=defaults.seed)
    parser.add_argument("--threads", type=int, default=defaults.threads)
    parser.add_argument("--batch", type=int, default=defaults.batch)
    parser.add_argument("--lr", type=float, default=defaults.lr)
    parser.add_argument("--ema-decay", type=float, default=defaults.ema_decay)
    parser.add_argument("--t-min", type=int, default=defaults.t_min, help="smallest training timestep")
    parser.add_argument("--t-max", type=int, default=defaults.t_max, help="largest training timestep")
    parser.add_argument("--train-views", type=int, default=defaults.train_views,
                        help="training cameras per demo object")
    parser.add_argument("--heldout-views", type=int, default=defaults.heldout_views,
                        help="held-out cameras per demo object")
    parser.add_argument("--image-size", type=int, default=defaults.image_size, help="render size of the demo objects")
    parser.add_argument("--window-jitter", type=float, default=defaults.window_jitter,
                        help="window scale 1.5 +- this")
    parser.add_argument("--gap-every", type=int, default=defaults.gap_every,
                        help="steps between loss-gap evaluations")
    parser.add_argument("--check-every-minutes", type=float, default=defaults.check_every_minutes,
                        help="minutes between inversion checks")
    parser.add_argument("--check-pairs", type=int, default=defaults.check_pairs)
    parser.add_argument("--gap-pairs", type=int, default=defaults.gap_pairs)
    parser.add_argument("--pool", type=int, default=defaults.pool, help="pairs kept in the rolling pair pool")
    parser.add_argument("--pool-refresh", type=int, default=defaults.pool_refresh, help="fresh pairs per step")
    parser.add_argument("--checkpoint-every-minutes", type=float, default=defaults.checkpoint_every_minutes)
    parser.add_argument("--block-out-channels", type=int, nargs="+", default=defaults.block_out_channels)
    parser.add_argument("--layers-per-block", type=int, default=defaults.layers_per_block)
    parser.add_argument("--prediction-type", choices=("epsilon", "sample"), default=defaults.prediction_type,
                        help="what the UNet outputs: noise, or the clean target (a view-synthesis loss)")
    parser.add_argument("--film", action=argparse.BooleanOptionalAction, default=defaults.film,
                        help="timestep+pose embedding scales and shifts every ResNet block (FiLM)")
    parser.add_argument("--token-in-timestep", action=argparse.BooleanOptionalAction,
                        default=defaults.token_in_timestep,
                        help="the cc_projection token (reference embedding + pose) also enters the timestep embedding")
    parser.add_argument("--rank-weight", type=float, default=defaults.rank_weight,
                        help="weight of the ranking loss: a wrong pose's error must exceed the true pose's (0: off)")
    parser.add_argument("--rank-margin", type=float, default=defaults.rank_margin,
                        help="the ranking loss's margin, as a share of the two errors' sum")
    parser.add_argument("--reference-warp", action=argparse.BooleanOptionalAction, default=defaults.reference_warp,
                        help="the UNet also sees the reference warped into the target view through a sphere")
    return parser.parse_args()


def main() -> None:
    train(TrainingOptions(**vars(parse_args())))


if __name__ == "__main__":
    main()
