#!/usr/bin/env python3
"""Train the embedded demo model on pybullet renders of the demo objects, on the CPU, resumably.

Renders its own data (cached as .npz in --work-dir), trains the small view-conditioned diffusion
model with an EMA of its weights, checkpoints every few minutes (rerun the same command to resume),
shows a progress bar with the loss and the true-vs-wrong-pose loss gap, logs the gap and a grid-search
inversion check (RotAcc on held-out views) to ``curve.csv`` and finally writes the EMA weights,
``solver_defaults.json`` and ``training.json`` into --out.

A growing share of the pairs are a robot's crops: the same cameras rendered again under random lamps with
shadows, in a camera's tone, the reference of each pair augmented by ``idpose_core.demo_model.robot_crops``; the
rest are the clean renders. The share is 0 while the model first learns to read the pose (``--robot-from`` of the
budget), then grows linearly to ``--robot-share`` over ``--robot-ramp`` of the budget. The loss gap and the
inversion check are logged on held-out clean pairs and on held-out robot crops.

    python scripts/train_demo_model.py    # 2.5 hours on 2 cores with the rendering (the shipped model: --minutes 150)
"""
from __future__ import annotations

import argparse
import csv
import json
import math
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
from idpose_core.demo_model import EMBEDDED_MODEL_DIR, DemoDiffusionModel, DemoModelConfig, DemoPredictor
from idpose_core.demo_model.grid_check import grid_search, pose_grid, rotation_errors
from idpose_core.demo_model.training_data import (
    PairBatch,
    PairPool,
    RenderedViews,
    RobotCrops,
    cached_lit,
    cached_views,
    make_pairs,
    random_pairs,
)
from idpose_core.metrics import random_pose_errors
from idpose_core.synthetic.scenes import demo_objects

GAP_TIMESTEPS = (400, 550, 700, 850)  # inside the default training range
CHECK_AZIMUTHS = 12
CHECK_POLARS_DEG = (-45.0, 0.0, 45.0)
WARM_UP = 0.02  # of the wall-time budget


def parse_args() -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", type=Path, default=EMBEDDED_MODEL_DIR, help="where the final model goes")
    parser.add_argument("--work-dir", type=Path, default=Path.home() / ".cache" / "idpose_demo_model",
                        help="render cache, checkpoint and curve.csv (not in git)")
    parser.add_argument("--minutes", type=float, default=147.0,
                        help="wall-time budget of the training (rendering the data takes about 2 more minutes)")
    parser.add_argument("--robot-share", type=float, default=0.6, help="share of the pairs that are robot crops")
    parser.add_argument("--robot-from", type=float, default=0.15,
                        help="share of the budget trained on clean renders only, before robot crops come in")
    parser.add_argument("--robot-ramp", type=float, default=0.25,
                        help="share of the budget over which the robot crops' share grows to --robot-share")
    parser.add_argument("--lamps", type=int, default=8, help="random lamps per object the cameras are rendered under")
    parser.add_argument("--max-steps", type=int, default=0, help="stop after this many steps (0: budget only)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--batch", type=int, default=32)
    parser.add_argument("--lr", type=float, default=8e-4)
    parser.add_argument("--ema-decay", type=float, default=0.998)
    parser.add_argument("--t-min", type=int, default=400, help="smallest training timestep")
    parser.add_argument("--t-max", type=int, default=950, help="largest training timestep")
    parser.add_argument("--train-views", type=int, default=600, help="training cameras per object")
    parser.add_argument("--heldout-views", type=int, default=60, help="held-out cameras per object")
    parser.add_argument("--image-size", type=int, default=128, help="render size before preprocessing")
    parser.add_argument("--window-jitter", type=float, default=0.2, help="window scale 1.5 +- this")
    parser.add_argument("--gap-every", type=int, default=100, help="steps between loss-gap evaluations")
    parser.add_argument("--check-every-minutes", type=float, default=15.0, help="minutes between inversion checks")
    parser.add_argument("--check-pairs", type=int, default=8)
    parser.add_argument("--gap-pairs", type=int, default=32)
    parser.add_argument("--pool", type=int, default=4096, help="pairs kept in the rolling pair pool")
    parser.add_argument("--pool-refresh", type=int, default=8, help="fresh pairs per step")
    parser.add_argument("--checkpoint-every-minutes", type=float, default=3.0)
    parser.add_argument("--block-out-channels", type=int, nargs="+", default=[32, 64, 128])
    parser.add_argument("--layers-per-block", type=int, default=1)
    parser.add_argument("--view-weight", type=float, default=1.0,
                        help="weight of the reference-view regression loss (absolute view conditioning)")
    parser.add_argument("--prediction-type", choices=("epsilon", "sample"), default="sample",
                        help="what the UNet outputs: noise, or the clean target (a view-synthesis loss)")
    parser.add_argument("--film", action=argparse.BooleanOptionalAction, default=True,
                        help="timestep+pose embedding scales and shifts every ResNet block (FiLM)")
    parser.add_argument("--token-in-timestep", action=argparse.BooleanOptionalAction, default=True,
                        help="the cc_projection token (reference embedding + pose) also enters the timestep embedding")
    return parser.parse_args()


def load_data(args: argparse.Namespace) -> tuple[RenderedViews, RenderedViews]:
    """Training and held-out renders of the demo objects (disjoint random cameras)."""
    specs = demo_objects()
    train = cached_views(args.work_dir / f"train_{args.seed}.npz", specs, args.train_views, args.image_size, args.seed)
    heldout = cached_views(args.work_dir / f"heldout_{args.seed}.npz", specs, args.heldout_views, args.image_size,
                           args.seed + 1000)
    return train, heldout


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


def training_loss(model: DemoDiffusionModel, reference: torch.Tensor, target: torch.Tensor, pose: torch.Tensor,
                  reference_view: torch.Tensor, t: torch.Tensor, view_weight: float
                  ) -> tuple[torch.Tensor, torch.Tensor]:
    """(total loss, denoising loss). Denoising: MSE of the UNet's output (noise or clean target, as the
    config's ``prediction_type`` says) at the true pose. With absolute view conditioning, plus
    ``view_weight`` x the MSE of the view head's (polar - pi/2, sin azimuth, cos azimuth) of the reference."""
    noise = torch.randn_like(target)
    noisy = model.add_noise(target, noise, t)
    wanted = target if model.config.prediction_type == "sample" else noise
    embedding = model.embed(reference)
    denoising = (model.model_output(noisy, reference, embedding, pose, t) - wanted).pow(2).mean()
    if model.view_head is None:
        return denoising, denoising
    polar, azimuth = reference_view[:, 0], reference_view[:, 1]
    wanted_view = torch.stack([polar - math.pi / 2, torch.sin(azimuth), torch.cos(azimuth)], -1)
    return denoising + view_weight * (model.view_head_output(embedding) - wanted_view).pow(2).mean(), denoising


def robot_share_at(progress: float, args: argparse.Namespace) -> float:
    """The share of robot crops among the fresh pairs at ``progress`` (0..1) of the budget."""
    ramp = (progress - args.robot_from) / args.robot_ramp if args.robot_ramp > 0 else float(progress >= args.robot_from)
    return args.robot_share * min(1.0, max(0.0, ramp))


def learning_rate_factor(progress: float) -> float:
    """Linear warm-up over the first WARM_UP of the wall-time budget, then a cosine decay to a tenth."""
    cosine = 0.5 * (1.0 + math.cos(math.pi * min(1.0, progress)))
    return min(1.0, max(progress, 1e-3) / WARM_UP) * (0.1 + 0.9 * cosine)


class HeldOut:
    """The held-out pairs the curve follows, per set (clean renders, robot crops): fixed pairs for the loss gap and
    for the inversion check."""

    def __init__(self, args: argparse.Namespace, views: RenderedViews, crops: RobotCrops, model: DemoDiffusionModel):
        self.views = views
        self.gap = {"clean": fixed_pairs(views, args.gap_pairs, args.seed + 1, model),
                    "robot": fixed_pairs(views, args.gap_pairs, args.seed + 4, model, crops)}
        self.check = {"clean": fixed_pairs(views, args.check_pairs, args.seed + 2, model),
                      "robot": fixed_pairs(views, args.check_pairs, args.seed + 5, model, crops)}
        self.seed = args.seed + 3

    def gaps(self, predictor: DemoPredictor) -> dict[str, dict[int, float]]:
        return {name: loss_gaps(predictor, pairs, self.seed) for name, pairs in self.gap.items()}

    def checks(self, predictor: DemoPredictor, t: int) -> dict[str, dict[str, float]]:
        return {name: inversion_check(predictor, pairs, self.views, t) for name, pairs in self.check.items()}


CURVE_SETS = ("clean", "robot")


def curve_header() -> list[str]:
    """Columns of curve.csv: the loss, the gap per held-out set and timestep, the inversion checks per set."""
    return (["step", "minutes", "loss"] + [f"{name}_gap_t{t}" for name in CURVE_SETS for t in GAP_TIMESTEPS]
            + ["check_t"] + [f"{name}_acc{a}" for name in CURVE_SETS for a in (15, 30)])


def describe(checks: dict[str, dict[str, float]]) -> str:
    return ", ".join(f"{name} RotAcc@15 {c['acc15']:.0%} @30 {c['acc30']:.0%}" for name, c in checks.items())


def main() -> None:
    args = parse_args()
    torch.set_num_threads(args.threads)
    torch.manual_seed(args.seed)
    args.work_dir.mkdir(parents=True, exist_ok=True)
    config = DemoModelConfig(block_out_channels=tuple(args.block_out_channels), layers_per_block=args.layers_per_block,
                             resnet_time_scale_shift="scale_shift" if args.film else "default",
                             token_in_timestep_embedding=args.token_in_timestep,
                             prediction_type=args.prediction_type)
    model = DemoDiffusionModel(config)
    optimizer = torch.optim.AdamW(model.parameters(), lr=args.lr, weight_decay=1e-4)
    ema = EMAModel(model.parameters(), decay=args.ema_decay)
    checkpoint_path = args.work_dir / "checkpoint.pt"
    step, elapsed, history = 0, 0.0, []
    if checkpoint_path.is_file():
        state = torch.load(checkpoint_path, weights_only=True)
        model.load_state_dict(state["model"])
        optimizer.load_state_dict(state["optimizer"])
        ema.load_state_dict(state["ema"])
        step, elapsed = int(state["step"]), float(state["elapsed"])
        history = json.loads(state.get("history", "[]"))
        print(f"resumed from {checkpoint_path} at step {step} ({elapsed / 60:.1f} min)")

    history.append({"from_step": step, "arguments": {k: str(v) if isinstance(v, Path) else v
                                                     for k, v in vars(args).items()}})
    train, heldout = load_data(args)
    specs = demo_objects()
    lamps = f"{args.seed}_{args.lamps}.npz"
    crops = RobotCrops(cached_lit(args.work_dir / f"lamps_{lamps}", specs, train, args.seed + 2000, args.lamps))
    heldout_crops = RobotCrops(cached_lit(args.work_dir / f"heldout_lamps_{lamps}", specs, heldout, args.seed + 3000,
                                          args.lamps))
    held_out = HeldOut(args, heldout, heldout_crops, model)
    baseline, _ = random_pose_errors(*map(spherical_to_c2w, true_cameras(held_out.check["clean"], heldout)), 200,
                                     np.random.default_rng(args.seed))
    print(f"random-pose baseline on the check pairs: RotAcc@15 {np.mean(baseline < 15):.0%}, "
          f"@30 {np.mean(baseline < 30):.0%}")
    curve_path = args.work_dir / "curve.csv"
    new_curve = not curve_path.is_file()
    curve = curve_path.open("a", newline="")
    writer = csv.writer(curve)
    if new_curve:
        writer.writerow(curve_header())

    budget = args.minutes * 60.0
    started = time.monotonic() - elapsed
    last_checkpoint = last_check = time.monotonic()
    gaps: dict[str, dict[int, float]] = {}
    losses: list[float] = []
    jitter = (1.5 - args.window_jitter, 1.5 + args.window_jitter)
    pool = PairPool(train, model.downsample, args.pool, args.pool_refresh, jitter, crops,
                    robot_share_at(elapsed / budget, args))
    pool.fill(np.random.default_rng([args.seed, step, 1]), min(512, args.pool))
    bar = tqdm(total=int(budget), initial=int(elapsed), unit="s", desc="train demo model")
    model.train()
    while True:
        elapsed = time.monotonic() - started
        if elapsed >= budget or (args.max_steps and step >= args.max_steps):
            break
        rng = np.random.default_rng([args.seed, step])
        pool.robot_share = robot_share_at(elapsed / budget, args)
        reference, target, pose, reference_view = pool.draw(rng, args.batch)
        t = torch.as_tensor(rng.integers(args.t_min, args.t_max + 1, size=args.batch))
        loss, denoising = training_loss(model, reference, target, pose, reference_view, t, args.view_weight)
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
            save_checkpoint(checkpoint_path, model, optimizer, ema, step, time.monotonic() - started, history)
            last_checkpoint = time.monotonic()
    bar.close()
    elapsed = time.monotonic() - started
    save_checkpoint(checkpoint_path, model, optimizer, ema, step, elapsed, history)
    predictor = ema_predictor(model, ema, config)
    gaps = held_out.gaps(predictor)
    best_t = probe_timestep(gaps, args)
    final = held_out.checks(predictor, best_t)
    print(f"final: step {step}, {elapsed / 60:.1f} min, gaps {gaps}, check at t={best_t}: {describe(final)}")
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
                        "lamps_per_object": args.lamps, "other_lamp": crops.other_lamp,
                        "reference": asdict(crops.reference), "target": asdict(crops.target)},
        "data": {"objects": list(train.names), "train_views_per_object": train.views_per_object,
                 "heldout_views_per_object": heldout.views_per_object, "image_size": args.image_size,
                 "polar_deg": [30, 150], "fov_deg": 60},
        "steps": step, "batch": args.batch, "wall_minutes": round(elapsed / 60, 1),
        "threads": args.threads, "loss_gap_by_t": gaps, "final_check": {"t": best_t, **final,
        "pairs": len(held_out.check["clean"].pose),
        "grid": f"{CHECK_AZIMUTHS} azimuths x polar offsets {CHECK_POLARS_DEG}"},
    }, indent=2) + "\n")
    curve.close()
    plot_curve(curve_path, args.work_dir / "curve.png")
    print(f"wrote {args.out} and {args.work_dir / 'curve.png'}")


def plot_curve(curve_path: Path, png_path: Path) -> None:
    """``curve.csv`` as a PNG: the loss gap at each probe timestep and the inversion checks vs minutes, per held-out
    set (solid: clean renders, dashed: robot crops)."""
    with curve_path.open() as handle:
        rows = list(csv.DictReader(handle))
    minutes = [float(row["minutes"]) for row in rows]
    figure, (gap_axes, check_axes) = plt.subplots(1, 2, figsize=(11, 4))
    for name, style in zip(CURVE_SETS, ("-", "--")):
        for index, t in enumerate(GAP_TIMESTEPS):
            gap_axes.plot(minutes, [100 * float(row[f"{name}_gap_t{t}"]) for row in rows], style, color=f"C{index}",
                          label=f"{name}, t = {t}")
    gap_axes.set(xlabel="training minutes", ylabel="loss gap, wrong vs true pose (%)", title="held-out pairs")
    gap_axes.legend(fontsize="small")
    checks = [row for row in rows if row["check_t"]]
    for name, style in zip(CURVE_SETS, ("o-", "s--")):
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
