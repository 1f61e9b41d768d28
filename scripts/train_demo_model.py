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
import csv
import json
import math
import shutil
import sys
import time
from dataclasses import asdict
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # run as a script from a checkout

import matplotlib  # noqa: E402 (after the path setup)
import numpy as np
import torch

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402 (after choosing the non-interactive backend)
from diffusers.training_utils import EMAModel
from tqdm import tqdm

from idpose_core.cameras import spherical_to_c2w
from idpose_core.demo_model import DemoDiffusionModel, DemoModelConfig, DemoPredictor
from idpose_core.demo_model.grid_check import grid_search, pose_grid, rotation_errors
from idpose_core.demo_model.training_data import (
    PairBatch,
    PairPool,
    PairSource,
    RenderedViews,
    RobotCrops,
    cached_lit,
    cached_views,
    make_pairs,
    random_pairs,
)
from idpose_core.metrics import random_pose_errors
from idpose_core.synthetic.catalogue import CURVE_HELDOUT, heldout_objects, training_objects
from idpose_core.synthetic.scenes import CAMERA_POLAR_DEG, FOV_DEG, demo_objects

GAP_TIMESTEPS = (400, 550, 700, 850)  # inside the default training range
CHECK_AZIMUTHS = 12
CHECK_POLARS_DEG = (-45.0, 0.0, 45.0)
WARM_UP = 0.02  # of the wall-time budget
CHECKPOINT_FILE = "checkpoint.pt"
WRONG_POLAR = 0.4  # radians: how far a wrong pose of the ranking loss moves the polar angle


def parse_args() -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", type=Path, help="where the model folder goes (default: WORK_DIR/model)")
    parser.add_argument("--work-dir", type=Path, default=Path.home() / ".cache" / "idpose_demo_model",
                        help="render cache, checkpoint and curve.csv (not in git)")
    parser.add_argument("--init-from", type=Path,
                        help="a model folder this script wrote (with training.json): go on from its weights, steps and "
                             "minutes when WORK_DIR holds no checkpoint (another machine, or a fresh cache)")
    parser.add_argument("--minutes", type=float, default=450.0,
                        help="training budget of the whole run, over every sitting: the learning rate and the robot "
                             "crops' share follow it")
    parser.add_argument("--chunk-minutes", type=float, default=150.0,
                        help="most training minutes of this sitting; rendering the data takes about 5 more")
    parser.add_argument("--demo-share", type=float, default=0.2, help="share of the pairs of the six demo objects")
    parser.add_argument("--toys", type=int, default=300, help="composed toys in the training catalogue")
    parser.add_argument("--mesh-variants", type=int, default=4, help="variants of every pybullet_data mesh")
    parser.add_argument("--blobs", type=int, default=800, help="training blobs (random_urdfs 000..)")
    parser.add_argument("--catalogue-views", type=int, default=32, help="cameras per catalogue object")
    parser.add_argument("--catalogue-size", type=int, default=96, help="render size of the catalogue objects")
    parser.add_argument("--heldout-objects", type=int, default=CURVE_HELDOUT[1],
                        help="held-out blobs (random_urdfs 800..) and as many held-out toys the curve follows")
    parser.add_argument("--robot-share", type=float, default=0.5, help="share of the pairs that are robot crops")
    parser.add_argument("--robot-from", type=float, default=0.15,
                        help="share of the budget trained on clean renders only, before robot crops come in")
    parser.add_argument("--robot-ramp", type=float, default=0.25,
                        help="share of the budget over which the robot crops' share grows to --robot-share")
    parser.add_argument("--lamps", type=int, default=8, help="random lamps per demo object its cameras are rendered "
                                                             "under (catalogue objects: one each)")
    parser.add_argument("--max-steps", type=int, default=0, help="stop after this many steps (0: budget only)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--batch", type=int, default=32)
    parser.add_argument("--lr", type=float, default=8e-4)
    parser.add_argument("--ema-decay", type=float, default=0.998)
    parser.add_argument("--t-min", type=int, default=400, help="smallest training timestep")
    parser.add_argument("--t-max", type=int, default=950, help="largest training timestep")
    parser.add_argument("--train-views", type=int, default=600, help="training cameras per demo object")
    parser.add_argument("--heldout-views", type=int, default=60, help="held-out cameras per demo object")
    parser.add_argument("--image-size", type=int, default=128, help="render size of the demo objects")
    parser.add_argument("--window-jitter", type=float, default=0.2, help="window scale 1.5 +- this")
    parser.add_argument("--gap-every", type=int, default=100, help="steps between loss-gap evaluations")
    parser.add_argument("--check-every-minutes", type=float, default=15.0, help="minutes between inversion checks")
    parser.add_argument("--check-pairs", type=int, default=24)
    parser.add_argument("--gap-pairs", type=int, default=32)
    parser.add_argument("--pool", type=int, default=4096, help="pairs kept in the rolling pair pool")
    parser.add_argument("--pool-refresh", type=int, default=8, help="fresh pairs per step")
    parser.add_argument("--checkpoint-every-minutes", type=float, default=3.0)
    parser.add_argument("--block-out-channels", type=int, nargs="+", default=[32, 64, 128])
    parser.add_argument("--layers-per-block", type=int, default=1)
    parser.add_argument("--prediction-type", choices=("epsilon", "sample"), default="sample",
                        help="what the UNet outputs: noise, or the clean target (a view-synthesis loss)")
    parser.add_argument("--film", action=argparse.BooleanOptionalAction, default=True,
                        help="timestep+pose embedding scales and shifts every ResNet block (FiLM)")
    parser.add_argument("--token-in-timestep", action=argparse.BooleanOptionalAction, default=True,
                        help="the cc_projection token (reference embedding + pose) also enters the timestep embedding")
    parser.add_argument("--rank-weight", type=float, default=0.05,
                        help="weight of the ranking loss: a wrong pose's error must exceed the true pose's (0: off)")
    parser.add_argument("--rank-margin", type=float, default=0.2,
                        help="the ranking loss's margin, as a share of the two errors' sum")
    parser.add_argument("--reference-warp", action=argparse.BooleanOptionalAction, default=True,
                        help="the UNet also sees the reference warped into the target view through a sphere")
    args = parser.parse_args()
    args.out = args.out or args.work_dir / "model"
    return args


class TrainingData:
    """Every render the run uses: the demo objects' training and held-out cameras, the training catalogue, the
    held-out catalogue, each with its robot-crop renders under lamps."""

    def __init__(self, args: argparse.Namespace):
        work, seed = args.work_dir, args.seed
        demo = demo_objects()
        self.demo = cached_views(work / f"train_{seed}.npz", demo, args.train_views, args.image_size, seed)
        self.demo_heldout = cached_views(work / f"heldout_{seed}.npz", demo, args.heldout_views, args.image_size,
                                         seed + 1000)
        self.demo_lit = cached_lit(work / f"lamps_{seed}_{args.lamps}.npz", demo, self.demo, seed + 2000, args.lamps)
        objects = training_objects(args.toys, args.mesh_variants, args.blobs, seed)
        self.catalogue = cached_views(work / f"catalogue_{seed}.npz", objects, args.catalogue_views,
                                      args.catalogue_size, seed + 4000)
        self.catalogue_lit = cached_lit(work / f"catalogue_lamps_{seed}.npz", objects, self.catalogue, seed + 5000, 1)
        held = heldout_objects(CURVE_HELDOUT[0], args.heldout_objects, seed)
        self.novel = cached_views(work / f"novel_{seed}.npz", held, 8, args.catalogue_size, seed + 6000)
        self.novel_lit = cached_lit(work / f"novel_lamps_{seed}.npz", held, self.novel, seed + 7000, 1)

    def sources(self, args: argparse.Namespace) -> list[PairSource]:
        """The pair pool's sources: the demo objects (``--demo-share`` of the pairs) and the catalogue."""
        return [PairSource(self.demo, RobotCrops(self.demo_lit), args.demo_share),
                PairSource(self.catalogue, RobotCrops(self.catalogue_lit), 1.0 - args.demo_share)]

    def names(self) -> dict[str, list[str]]:
        """The objects of each part of the data, as training.json records them."""
        return {"demo": list(self.demo.names), "catalogue": list(self.catalogue.names),
                "heldout": list(self.novel.names)}


def fixed_pairs(views: RenderedViews, count: int, seed: int, model: DemoDiffusionModel,
                crops: RobotCrops | None = None) -> PairBatch:
    """A fixed set of held-out pairs (window scale 1.5, as at inference), as robot crops when ``crops`` are given."""
    rng = np.random.default_rng(seed)
    return make_pairs(views, *random_pairs(views, rng, count), model.downsample, crops=crops, rng=rng)


@torch.no_grad()
def loss_gaps(predictor: DemoPredictor, pairs: PairBatch, seed: int) -> dict[int, float]:
    """Relative loss gap (wrong - true) / true at each of GAP_TIMESTEPS, same noise for both poses."""
    rng = np.random.default_rng(seed)
    count = len(pairs.pose)
    wrong = pairs.pose.clone()
    wrong[:, 1] = torch.remainder(wrong[:, 1] + torch.as_tensor(rng.uniform(math.pi / 3, 5 * math.pi / 3, count),
                                                                dtype=torch.float32), 2 * math.pi)
    views = predictor.encode(torch.cat([pairs.reference, pairs.target]))
    ref, tgt = torch.arange(count), torch.arange(count) + count
    noise = torch.randn((count, *views.noise_shape), generator=torch.Generator().manual_seed(seed))
    gaps = {}
    for t in GAP_TIMESTEPS:
        steps = torch.full((count,), t, dtype=torch.long)
        true_loss = predictor.noise_error(views, ref, tgt, pairs.pose, steps, noise).mean()
        wrong_loss = predictor.noise_error(views, ref, tgt, wrong, steps, noise).mean()
        gaps[t] = float((wrong_loss - true_loss) / true_loss)
    return gaps


def probe_timestep(gaps: dict[str, dict[int, float]], args: argparse.Namespace) -> int:
    """The timestep with the largest loss gap, summed over the held-out sets, among those the model was trained at
    (the solver probes there)."""
    trained = [t for t in GAP_TIMESTEPS if args.t_min <= t <= args.t_max]
    if not trained:
        raise ValueError(f"no loss-gap timestep {GAP_TIMESTEPS} lies in the training range "
                         f"[{args.t_min}, {args.t_max}]")
    return max(trained, key=lambda t: sum(by_t[t] for by_t in gaps.values()))


def inversion_check(predictor: DemoPredictor, pairs: PairBatch, views: RenderedViews, t: int) -> dict[str, float]:
    """Grid-search RotAcc@15/30 on held-out pairs (exploration only, one noise sample: cheap and coarse)."""
    candidates = pose_grid(CHECK_AZIMUTHS, CHECK_POLARS_DEG)
    predicted = grid_search(predictor, pairs.reference, pairs.target, candidates, t, noise_samples=1)
    errors = rotation_errors(predicted, *true_cameras(pairs, views))
    return {"acc15": float(np.mean(errors < 15)), "acc30": float(np.mean(errors < 30))}


def true_cameras(pairs: PairBatch, views: RenderedViews) -> tuple[np.ndarray, np.ndarray]:
    """Absolute cameras (P, 3) of the pairs' references and targets."""
    return (views.cameras[pairs.object_index, pairs.reference_index],
            views.cameras[pairs.object_index, pairs.target_index])


def ema_predictor(model: DemoDiffusionModel, ema: EMAModel, config: DemoModelConfig) -> DemoPredictor:
    """A frozen copy of the model carrying the EMA weights."""
    copy = DemoDiffusionModel(config)
    copy.load_state_dict(model.state_dict())
    ema.copy_to(copy.parameters())
    return DemoPredictor(copy)


def wrong_poses(pose: torch.Tensor, rng: np.random.Generator) -> torch.Tensor:
    """For relative poses (B, 3), wrong ones (B, 3): the azimuth turned by 30..330 deg, the polar moved by up to
    WRONG_POLAR radians."""
    count = len(pose)
    turn = torch.as_tensor(rng.uniform(math.pi / 6, 11 * math.pi / 6, count), dtype=pose.dtype)
    tilt = torch.as_tensor(rng.uniform(-WRONG_POLAR, WRONG_POLAR, count), dtype=pose.dtype)
    return torch.stack([pose[:, 0] + tilt, torch.remainder(pose[:, 1] + turn, 2 * math.pi), pose[:, 2]], -1)


def training_loss(model: DemoDiffusionModel, reference: torch.Tensor, target: torch.Tensor, pose: torch.Tensor,
                  wrong: torch.Tensor, t: torch.Tensor, rank_weight: float, rank_margin: float
                  ) -> tuple[torch.Tensor, torch.Tensor]:
    """(total loss, denoising loss). Denoising: MSE of the UNet's output (noise or clean target, as the config's
    ``prediction_type`` says) at the true relative pose. Ranking: the same error under a ``wrong`` pose (same noise,
    same step) must exceed the true pose's by ``rank_margin`` of their sum (a hinge, weighted by ``rank_weight``):
    what the solver's inversion needs, the true pose's error the lowest."""
    noise = torch.randn_like(target)
    noisy = model.add_noise(target, noise, t)
    wanted = target if model.config.prediction_type == "sample" else noise
    embedding = model.embed(reference)
    if rank_weight == 0:
        denoising = (model.model_output(noisy, reference, embedding, pose, t) - wanted).pow(2).mean()
        return denoising, denoising
    output = model.model_output(noisy.repeat(2, 1, 1, 1), reference.repeat(2, 1, 1, 1), embedding.repeat(2, 1),
                                torch.cat([pose, wrong]), t.repeat(2))
    true_error, wrong_error = (output - wanted.repeat(2, 1, 1, 1)).pow(2).flatten(1).mean(1).chunk(2)
    gap = (wrong_error - true_error) / (wrong_error + true_error).detach()
    denoising = true_error.mean()
    return denoising + rank_weight * torch.relu(rank_margin - gap).mean(), denoising


def robot_share_at(progress: float, args: argparse.Namespace) -> float:
    """The share of robot crops among the fresh pairs at ``progress`` (0..1) of the budget."""
    ramp = (progress - args.robot_from) / args.robot_ramp if args.robot_ramp > 0 else float(progress >= args.robot_from)
    return args.robot_share * min(1.0, max(0.0, ramp))


def learning_rate_factor(progress: float) -> float:
    """Linear warm-up over the first WARM_UP of the wall-time budget, then a cosine decay to a tenth."""
    cosine = 0.5 * (1.0 + math.cos(math.pi * min(1.0, progress)))
    return min(1.0, max(progress, 1e-3) / WARM_UP) * (0.1 + 0.9 * cosine)


CURVE_SETS = ("novel", "novel_robot", "demo")
"""The held-out sets the curve follows: clean pairs of held-out objects, the same objects as a robot's crops, and
held-out cameras of the six demo objects."""


class HeldOut:
    """The held-out pairs the curve follows, per set of CURVE_SETS: fixed pairs for the loss gap and for the
    inversion check."""

    def __init__(self, args: argparse.Namespace, data: TrainingData, model: DemoDiffusionModel):
        crops = RobotCrops(data.novel_lit)
        self.views = {"novel": data.novel, "novel_robot": data.novel, "demo": data.demo_heldout}
        self.gap = {"novel": fixed_pairs(data.novel, args.gap_pairs, args.seed + 1, model),
                    "novel_robot": fixed_pairs(data.novel, args.gap_pairs, args.seed + 4, model, crops),
                    "demo": fixed_pairs(data.demo_heldout, args.gap_pairs, args.seed + 6, model)}
        self.check = {"novel": fixed_pairs(data.novel, args.check_pairs, args.seed + 2, model),
                      "novel_robot": fixed_pairs(data.novel, args.check_pairs, args.seed + 5, model, crops),
                      "demo": fixed_pairs(data.demo_heldout, args.check_pairs, args.seed + 7, model)}
        self.seed = args.seed + 3

    def gaps(self, predictor: DemoPredictor) -> dict[str, dict[int, float]]:
        return {name: loss_gaps(predictor, pairs, self.seed) for name, pairs in self.gap.items()}

    def checks(self, predictor: DemoPredictor, t: int) -> dict[str, dict[str, float]]:
        return {name: inversion_check(predictor, pairs, self.views[name], t) for name, pairs in self.check.items()}

    def random_baseline(self, seed: int) -> str:
        """RotAcc@15/30 of random poses on the novel check pairs."""
        errors, _ = random_pose_errors(*map(spherical_to_c2w, true_cameras(self.check["novel"], self.views["novel"])),
                                       200, np.random.default_rng(seed))
        return f"RotAcc@15 {np.mean(errors < 15):.0%}, @30 {np.mean(errors < 30):.0%}"


def curve_header() -> list[str]:
    """Columns of curve.csv: the loss, the gap per held-out set and timestep, the inversion checks per set."""
    return (["step", "minutes", "loss"] + [f"{name}_gap_t{t}" for name in CURVE_SETS for t in GAP_TIMESTEPS]
            + ["check_t"] + [f"{name}_acc{a}" for name in CURVE_SETS for a in (15, 30)])


def describe(checks: dict[str, dict[str, float]]) -> str:
    return ", ".join(f"{name} RotAcc@15 {c['acc15']:.0%} @30 {c['acc30']:.0%}" for name, c in checks.items())


def model_config(args: argparse.Namespace) -> DemoModelConfig:
    """The architecture the arguments ask for: relative poses only (no absolute view head)."""
    return DemoModelConfig(block_out_channels=tuple(args.block_out_channels), layers_per_block=args.layers_per_block,
                           resnet_time_scale_shift="scale_shift" if args.film else "default",
                           token_in_timestep_embedding=args.token_in_timestep, prediction_type=args.prediction_type,
                           absolute_view_conditioning=False, reference_warp=args.reference_warp)


def restore(args: argparse.Namespace, model: DemoDiffusionModel, optimizer: torch.optim.Optimizer, ema: EMAModel
            ) -> tuple[int, float, list[dict]]:
    """(step, training seconds, history) to go on from: the work dir's checkpoint (exactly), else ``--init-from``'s
    model folder (its weights as model and EMA, a fresh optimizer), else a fresh start."""
    checkpoint_path = args.work_dir / CHECKPOINT_FILE
    if checkpoint_path.is_file():
        state = torch.load(checkpoint_path, weights_only=True)
        model.load_state_dict(state["model"])
        optimizer.load_state_dict(state["optimizer"])
        ema.load_state_dict(state["ema"])
        print(f"resumed from {checkpoint_path} at step {state['step']} ({state['elapsed'] / 60:.1f} min)")
        return int(state["step"]), float(state["elapsed"]), json.loads(state["history"])
    if args.init_from is not None:
        records = json.loads((args.init_from / "training.json").read_text())
        model.load_state_dict(DemoDiffusionModel.from_pretrained(args.init_from).state_dict())
        ema.load_state_dict({**ema.state_dict(), "shadow_params": [p.detach().clone() for p in model.parameters()]})
        print(f"initialised from {args.init_from} at step {records['steps']} ({records['wall_minutes']:.1f} min)")
        return int(records["steps"]), 60.0 * float(records["wall_minutes"]), records["phases"]
    return 0, 0.0, []


def main() -> None:
    args = parse_args()
    torch.set_num_threads(args.threads)
    torch.manual_seed(args.seed)
    args.work_dir.mkdir(parents=True, exist_ok=True)
    config = model_config(args)
    model = DemoDiffusionModel(config)
    optimizer = torch.optim.AdamW(model.parameters(), lr=args.lr, weight_decay=1e-4)
    ema = EMAModel(model.parameters(), decay=args.ema_decay)
    step, elapsed, history = restore(args, model, optimizer, ema)
    history.append({"from_step": step, "arguments": {k: str(v) if isinstance(v, Path) else v
                                                     for k, v in vars(args).items()}})
    data = TrainingData(args)
    held_out = HeldOut(args, data, model)
    print(f"{data.catalogue.num_objects} catalogue + {data.demo.num_objects} demo objects; random poses on the "
          f"held-out check pairs: {held_out.random_baseline(args.seed)}")
    curve_path = args.work_dir / "curve.csv"
    if not curve_path.is_file() and args.init_from is not None and (args.init_from / "curve.csv").is_file():
        shutil.copyfile(args.init_from / "curve.csv", curve_path)  # the lineage's curve goes on where it stopped
    new_curve = not curve_path.is_file()
    curve = curve_path.open("a", newline="")
    writer = csv.writer(curve)
    if new_curve:
        writer.writerow(curve_header())

    budget = args.minutes * 60.0
    stop_at = min(budget, elapsed + args.chunk_minutes * 60.0)
    started = time.monotonic() - elapsed
    last_checkpoint = last_check = time.monotonic()
    gaps: dict[str, dict[int, float]] = {}
    losses: list[float] = []
    jitter = (1.5 - args.window_jitter, 1.5 + args.window_jitter)
    pool = PairPool(data.sources(args), model.downsample, args.pool, args.pool_refresh, jitter,
                    robot_share_at(elapsed / budget, args))
    pool.fill(np.random.default_rng([args.seed, step, 1]), min(512, args.pool))
    bar = tqdm(total=int(stop_at), initial=int(elapsed), unit="s", desc="train model")
    model.train()
    while True:
        elapsed = time.monotonic() - started
        if elapsed >= stop_at or (args.max_steps and step >= args.max_steps):
            break
        rng = np.random.default_rng([args.seed, step])
        pool.robot_share = robot_share_at(elapsed / budget, args)
        reference, target, pose = pool.draw(rng, args.batch)
        t = torch.as_tensor(rng.integers(args.t_min, args.t_max + 1, size=args.batch))
        loss, denoising = training_loss(model, reference, target, pose, wrong_poses(pose, rng), t, args.rank_weight,
                                        args.rank_margin)
        optimizer.zero_grad(set_to_none=True)
        loss.backward()
        torch.nn.utils.clip_grad_norm_(model.parameters(), 1.0)
        for group in optimizer.param_groups:
            group["lr"] = args.lr * learning_rate_factor(elapsed / budget)
        optimizer.step()
        ema.step(model.parameters())
        step += 1
        losses.append(denoising.item())

        row_check = [""] * (1 + 2 * len(CURVE_SETS))
        now = time.monotonic()
        if step % args.gap_every == 0 or now - last_check >= args.check_every_minutes * 60.0:
            predictor = ema_predictor(model, ema, config)
            gaps = held_out.gaps(predictor)
            if now - last_check >= args.check_every_minutes * 60.0:
                best_t = probe_timestep(gaps, args)
                checks = held_out.checks(predictor, best_t)
                row_check = [best_t] + [checks[name][f"acc{a}"] for name in CURVE_SETS for a in (15, 30)]
                tqdm.write(f"step {step}: inversion check at t={best_t}: {describe(checks)}")
                last_check = time.monotonic()
            writer.writerow([step, round((time.monotonic() - started) / 60, 2), round(float(np.mean(losses)), 5)]
                            + [round(gaps[name][t], 4) for name in CURVE_SETS for t in GAP_TIMESTEPS] + row_check)
            curve.flush()
            losses = []
            model.train()
        best = {name: max(by_t.values()) for name, by_t in gaps.items()}
        bar.set_postfix(step=step, loss=f"{losses[-1] if losses else 0:.4f}", robot=f"{pool.robot_share:.0%}",
                        gap="/".join(f"{best.get(name, 0.0):+.0%}" for name in CURVE_SETS))
        bar.update(int(time.monotonic() - started) - bar.n)
        if time.monotonic() - last_checkpoint >= args.checkpoint_every_minutes * 60.0:
            save_checkpoint(args.work_dir / CHECKPOINT_FILE, model, optimizer, ema, step, time.monotonic() - started,
                            history)
            last_checkpoint = time.monotonic()
    bar.close()
    elapsed = time.monotonic() - started
    save_checkpoint(args.work_dir / CHECKPOINT_FILE, model, optimizer, ema, step, elapsed, history)
    predictor = ema_predictor(model, ema, config)
    gaps = held_out.gaps(predictor)
    best_t = probe_timestep(gaps, args)
    final = held_out.checks(predictor, best_t)
    print(f"step {step}, {elapsed / 60:.1f} of {args.minutes:.0f} min, gaps {gaps}, check at t={best_t}: "
          f"{describe(final)}")
    predictor.model.save_pretrained(args.out)
    probe_t = best_t / config.num_train_timesteps
    (args.out / "solver_defaults.json").write_text(json.dumps(  # start_t_range: the annealed starts end at probe_t
        {"probe_t": probe_t, "refine_t_range": [probe_t, (best_t + 10) / config.num_train_timesteps],
         "start_t_range": [max(args.t_max / config.num_train_timesteps, probe_t), probe_t]},
        indent=2) + "\n")
    (args.out / "training.json").write_text(json.dumps({
        "script": "scripts/train_demo_model.py",
        "seed": args.seed,
        "phases": history,
        "config": asdict(config),
        "robot_crops": {"share": args.robot_share, "from": args.robot_from, "ramp": args.robot_ramp,
                        "lamps_per_demo_object": args.lamps, "lamps_per_catalogue_object": 1,
                        "reference": asdict(RobotCrops.reference), "target": asdict(RobotCrops.target)},
        "data": {"objects": data.names(), "demo_share": args.demo_share,
                 "demo_views_per_object": data.demo.views_per_object,
                 "catalogue_views_per_object": data.catalogue.views_per_object,
                 "heldout_views_per_object": data.novel.views_per_object, "polar_deg": list(CAMERA_POLAR_DEG),
                 "fov_deg": FOV_DEG},
        "steps": step, "batch": args.batch, "wall_minutes": round(elapsed / 60, 1), "budget_minutes": args.minutes,
        "finished": elapsed >= budget, "threads": args.threads, "loss_gap_by_t": gaps,
        "final_check": {"t": best_t, **final, "pairs": len(held_out.check["novel"].pose),
                        "grid": f"{CHECK_AZIMUTHS} azimuths x polar offsets {CHECK_POLARS_DEG}"},
    }, indent=2) + "\n")
    curve.close()
    shutil.copyfile(curve_path, args.out / "curve.csv")
    plot_curve(curve_path, args.out / "curve.png")
    print(f"wrote {args.out} with its curve.csv and curve.png")


def plot_curve(curve_path: Path, png_path: Path) -> None:
    """``curve.csv`` as a PNG: the loss gap at each probe timestep and the inversion checks vs minutes, per held-out
    set (solid: novel objects, dashed: novel objects as a robot's crops, dotted: the demo objects)."""
    with curve_path.open() as handle:
        rows = list(csv.DictReader(handle))
    minutes = [float(row["minutes"]) for row in rows]
    figure, (gap_axes, check_axes) = plt.subplots(1, 2, figsize=(11, 4))
    for name, style in zip(CURVE_SETS, ("-", "--", ":")):
        for index, t in enumerate(GAP_TIMESTEPS):
            gap_axes.plot(minutes, [100 * float(row[f"{name}_gap_t{t}"]) for row in rows], style, color=f"C{index}",
                          label=f"{name}, t = {t}")
    gap_axes.set(xlabel="training minutes", ylabel="loss gap, wrong vs true pose (%)", title="held-out pairs")
    gap_axes.legend(fontsize="small")
    checks = [row for row in rows if row["check_t"]]
    for name, style in zip(CURVE_SETS, ("o-", "s--", "^:")):
        for index, accuracy in enumerate((15, 30)):
            check_axes.plot([float(row["minutes"]) for row in checks],
                            [100 * float(row[f"{name}_acc{accuracy}"]) for row in checks], style, color=f"C{index}",
                            label=f"{name}, RotAcc@{accuracy}")
    check_axes.set(xlabel="training minutes", ylabel="%", ylim=(0, 100),
                   title="grid-search inversion check (held-out pairs)")
    check_axes.legend(fontsize="small")
    figure.tight_layout()
    figure.savefig(png_path, dpi=100)
    plt.close(figure)


def save_checkpoint(path: Path, model: DemoDiffusionModel, optimizer: torch.optim.Optimizer, ema: EMAModel,
                    step: int, elapsed: float, history: list[dict]) -> None:
    """Atomically write everything needed to resume (``history``: the arguments of every start and resume)."""
    temporary = path.with_suffix(".tmp")
    torch.save({"model": model.state_dict(), "optimizer": optimizer.state_dict(), "ema": ema.state_dict(),
                "step": step, "elapsed": elapsed, "history": json.dumps(history)}, temporary)
    temporary.replace(path)


if __name__ == "__main__":
    main()
