#!/usr/bin/env python3
"""Train the embedded demo model on pybullet renders of the demo objects, on the CPU, resumably.

Renders its own data (cached as .npz in --work-dir), trains the small view-conditioned diffusion
model with an EMA of its weights, checkpoints every few minutes (rerun the same command to resume),
shows a progress bar with the loss and the true-vs-wrong-pose loss gap, logs the gap and a grid-search
inversion check (RotAcc on held-out views) to ``curve.csv`` and finally writes the EMA weights,
``solver_defaults.json`` and ``training.json`` into --out.

    python scripts/train_demo_model.py --minutes 100 --threads 1
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

import numpy as np  # noqa: E402 (after the path setup)
import torch
from diffusers.training_utils import EMAModel
from tqdm import tqdm

from idpose_core.demo_model import EMBEDDED_MODEL_DIR, DemoDiffusionModel, DemoModelConfig, DemoPredictor
from idpose_core.demo_model.grid_check import grid_search, pose_grid, random_pose_errors, rotation_errors
from idpose_core.demo_model.training_data import (PairBatch, PairPool, RenderedViews, cached_views, make_pairs,
                                                  random_pairs)
from idpose_core.synthetic.scenes import demo_objects

GAP_TIMESTEPS = (200, 350, 500, 650)
CHECK_AZIMUTHS = 12
CHECK_POLARS_DEG = (-45.0, 0.0, 45.0)
POSE_PATH = ("class_embedding", "time_emb_proj", "cc_projection")


def parse_args() -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", type=Path, default=EMBEDDED_MODEL_DIR, help="where the final model goes")
    parser.add_argument("--work-dir", type=Path, default=Path.home() / ".cache" / "idpose_demo_model",
                        help="render cache, checkpoint and curve.csv (not in git)")
    parser.add_argument("--minutes", type=float, default=100.0, help="training wall-time budget")
    parser.add_argument("--max-steps", type=int, default=0, help="stop after this many steps (0: budget only)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--batch", type=int, default=32)
    parser.add_argument("--lr", type=float, default=8e-4)
    parser.add_argument("--ema-decay", type=float, default=0.998)
    parser.add_argument("--t-min", type=int, default=100, help="smallest training timestep")
    parser.add_argument("--t-max", type=int, default=800, help="largest training timestep")
    parser.add_argument("--train-views", type=int, default=600, help="training cameras per object")
    parser.add_argument("--heldout-views", type=int, default=60, help="held-out cameras per object")
    parser.add_argument("--image-size", type=int, default=128, help="render size before preprocessing")
    parser.add_argument("--window-jitter", type=float, default=0.2, help="window scale 1.5 +- this")
    parser.add_argument("--gap-every", type=int, default=100, help="steps between loss-gap evaluations")
    parser.add_argument("--check-every-minutes", type=float, default=20.0, help="minutes between inversion checks")
    parser.add_argument("--check-pairs", type=int, default=8)
    parser.add_argument("--gap-pairs", type=int, default=32)
    parser.add_argument("--pool", type=int, default=4096, help="pairs kept in the rolling pair pool")
    parser.add_argument("--pool-refresh", type=int, default=8, help="fresh pairs per step")
    parser.add_argument("--checkpoint-every-minutes", type=float, default=3.0)
    parser.add_argument("--block-out-channels", type=int, nargs="+", default=[32, 64, 128])
    parser.add_argument("--layers-per-block", type=int, default=1)
    parser.add_argument("--film", action=argparse.BooleanOptionalAction, default=True,
                        help="timestep+pose embedding scales and shifts every ResNet block (FiLM)")
    parser.add_argument("--token-in-timestep", action=argparse.BooleanOptionalAction, default=True,
                        help="the cc_projection token (reference embedding + pose) also enters the timestep embedding")
    parser.add_argument("--rank-weight", type=float, default=0.1,
                        help="weight of the pose-ranking term (0: plain denoising loss)")
    parser.add_argument("--rank-margin", type=float, default=0.3,
                        help="relative noise-error margin a wrong pose must exceed the true pose by")
    parser.add_argument("--rank-pairs", type=int, default=16, help="pairs per batch that also get a wrong pose")
    parser.add_argument("--init-from", type=Path, default=None,
                        help="start from this checkpoint's model weights (a non-FiLM one may seed a --film model)")
    parser.add_argument("--pose-lr-scale", type=float, default=10.0,
                        help="learning-rate factor of the pose path (class embedding, time_emb_proj, cc_projection)")
    parser.add_argument("--rank-start-step", type=int, default=0, help="step from which the ranking term is on")
    return parser.parse_args()


def load_data(args: argparse.Namespace) -> tuple[RenderedViews, RenderedViews]:
    """Training and held-out renders of the demo objects (disjoint random cameras)."""
    specs = demo_objects()
    train = cached_views(args.work_dir / f"train_{args.seed}.npz", specs, args.train_views, args.image_size, args.seed)
    heldout = cached_views(args.work_dir / f"heldout_{args.seed}.npz", specs, args.heldout_views, args.image_size,
                           args.seed + 1000)
    return train, heldout


def fixed_pairs(views: RenderedViews, count: int, seed: int, model: DemoDiffusionModel) -> PairBatch:
    """A fixed set of held-out pairs (window scale 1.5, as at inference)."""
    return make_pairs(views, *random_pairs(views, np.random.default_rng(seed), count), model.downsample)


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
    """Perturbed poses (B, 3): mostly a different azimuth (20..340 deg off) with some polar change,
    otherwise the same azimuth and a polar 15..50 deg off; the radius stays."""
    count = len(pose)
    azimuth_off = rng.uniform(math.radians(20), math.radians(340), count)
    polar_off = rng.uniform(-math.radians(40), math.radians(40), count)
    polar_only = rng.random(count) < 0.3
    azimuth_off[polar_only] = 0.0
    polar_off[polar_only] = rng.choice([-1.0, 1.0], polar_only.sum()) * rng.uniform(
        math.radians(15), math.radians(50), polar_only.sum())
    wrong = pose.clone()
    wrong[:, 0] += torch.as_tensor(polar_off, dtype=pose.dtype)
    wrong[:, 1] = torch.remainder(wrong[:, 1] + torch.as_tensor(azimuth_off, dtype=pose.dtype), 2 * math.pi)
    return wrong


def training_loss(model: DemoDiffusionModel, reference: torch.Tensor, target: torch.Tensor, pose: torch.Tensor,
                  t: torch.Tensor, rng: np.random.Generator, rank_pairs: int, rank_weight: float,
                  rank_margin: float) -> tuple[torch.Tensor, torch.Tensor]:
    """(total loss, denoising loss). Denoising: noise MSE at the true pose. Ranking (this model's
    deviation from Zero-1-to-3's objective): the first ``rank_pairs`` samples are also denoised under a
    wrong pose with the same noise, and a hinge asks their error to exceed the true pose's by
    ``rank_margin`` (relative); it switches itself off once the margin holds."""
    noise = torch.randn_like(target)
    noisy = model.add_noise(target, noise, t)
    embedding = model.embed(reference)
    k = rank_pairs if rank_weight > 0 else 0
    predicted = model.predict_noise(torch.cat([noisy, noisy[:k]]), torch.cat([reference, reference[:k]]),
                                    torch.cat([embedding, embedding[:k]]),
                                    torch.cat([pose, wrong_poses(pose[:k], rng)]), torch.cat([t, t[:k]]))
    errors = (predicted - torch.cat([noise, noise[:k]])).pow(2).flatten(1).mean(1)
    true_errors, wrong_errors = errors[:len(pose)], errors[len(pose):]
    denoising = true_errors.mean()
    if k == 0:
        return denoising, denoising
    gap = (wrong_errors - true_errors[:k]) / true_errors[:k].detach().clamp_min(1e-4)
    return denoising + rank_weight * torch.relu(rank_margin - gap).mean(), denoising


def initial_weights(path: Path, model: DemoDiffusionModel) -> tuple[int, float]:
    """Load a checkpoint's model weights into ``model``; returns its (step, elapsed seconds).

    A checkpoint without FiLM seeds a FiLM model: each ResNet's ``time_emb_proj`` (C -> 2C) gets zero
    scale rows and the old additive projection as its shift rows; new class-embedding inputs (the
    token) get zero weights; every other tensor is copied.
    """
    state = torch.load(path, weights_only=True)
    weights = model.state_dict()
    for name, tensor in state["model"].items():
        if weights[name].shape == tensor.shape:
            weights[name] = tensor
        elif "time_emb_proj" in name and weights[name].shape[0] == 2 * tensor.shape[0]:
            weights[name] = torch.cat([torch.zeros_like(tensor), tensor])
        elif name == "unet.class_embedding.linear_1.weight" and weights[name].shape[0] == tensor.shape[0]:
            weights[name] = torch.cat([tensor, torch.zeros(tensor.shape[0], weights[name].shape[1] - tensor.shape[1])], 1)
        else:
            raise ValueError(f"{path}: {name} has shape {tuple(tensor.shape)}, the model needs {tuple(weights[name].shape)}")
    model.load_state_dict(weights)
    return int(state["step"]), float(state["elapsed"])


def main() -> None:
    args = parse_args()
    torch.set_num_threads(args.threads)
    torch.manual_seed(args.seed)
    args.work_dir.mkdir(parents=True, exist_ok=True)
    config = DemoModelConfig(block_out_channels=tuple(args.block_out_channels), layers_per_block=args.layers_per_block,
                             resnet_time_scale_shift="scale_shift" if args.film else "default",
                             token_in_timestep_embedding=args.token_in_timestep)
    model = DemoDiffusionModel(config)
    pose_path = [p for n, p in model.named_parameters() if any(k in n for k in POSE_PATH)]
    rest = [p for n, p in model.named_parameters() if not any(k in n for k in POSE_PATH)]
    optimizer = torch.optim.AdamW([{"params": rest, "scale": 1.0}, {"params": pose_path, "scale": args.pose_lr_scale}],
                                  lr=args.lr, weight_decay=1e-4)
    ema = EMAModel(model.parameters(), decay=args.ema_decay)
    checkpoint_path = args.work_dir / "checkpoint.pt"
    step, elapsed, history = 0, 0.0, []
    if checkpoint_path.is_file():
        state = torch.load(checkpoint_path, weights_only=True)
        model.load_state_dict(state["model"])
        try:
            optimizer.load_state_dict(state["optimizer"])
        except ValueError as error:  # a checkpoint from before the pose-path parameter group
            print(f"optimizer state not resumed ({error}); starting it afresh")
        ema.load_state_dict(state["ema"])
        step, elapsed = int(state["step"]), float(state["elapsed"])
        history = json.loads(state.get("history", "[]"))
        print(f"resumed from {checkpoint_path} at step {step} ({elapsed / 60:.1f} min)")
    elif args.init_from is not None:
        step, elapsed = initial_weights(args.init_from, model)
        ema = EMAModel(model.parameters(), decay=args.ema_decay)
        history = [{"from_step": step, "initialised_from": str(args.init_from)}]
        print(f"initialised from {args.init_from} (step {step}, {elapsed / 60:.1f} min)")

    history.append({"from_step": step, "arguments": {k: str(v) if isinstance(v, Path) else v
                                                     for k, v in vars(args).items()}})
    train, heldout = load_data(args)
    gap_pairs = fixed_pairs(heldout, args.gap_pairs, args.seed + 1, model)
    check_pairs = fixed_pairs(heldout, args.check_pairs, args.seed + 2, model)
    baseline = random_pose_errors(*true_cameras(check_pairs, heldout), np.random.default_rng(args.seed),
                                  CHECK_POLARS_DEG)
    print(f"random-pose baseline on the check pairs: RotAcc@15 {np.mean(baseline < 15):.0%}, "
          f"@30 {np.mean(baseline < 30):.0%}")
    curve_path = args.work_dir / "curve.csv"
    new_curve = not curve_path.is_file()
    curve = curve_path.open("a", newline="")
    writer = csv.writer(curve)
    if new_curve:
        writer.writerow(["step", "minutes", "loss"] + [f"gap_t{t}" for t in GAP_TIMESTEPS]
                        + ["check_t", "acc15", "acc30"])

    budget = args.minutes * 60.0
    started = time.monotonic() - elapsed
    last_checkpoint = last_check = time.monotonic()
    gaps: dict[int, float] = {}
    losses: list[float] = []
    jitter = (1.5 - args.window_jitter, 1.5 + args.window_jitter)
    pool = PairPool(train, model.downsample, args.pool, args.pool_refresh, jitter)
    pool.fill(np.random.default_rng([args.seed, step, 1]), min(512, args.pool))
    bar = tqdm(total=int(budget), initial=int(elapsed), unit="s", desc="train demo model")
    model.train()
    while True:
        elapsed = time.monotonic() - started
        if elapsed >= budget or (args.max_steps and step >= args.max_steps):
            break
        rng = np.random.default_rng([args.seed, step])
        reference, target, pose = pool.draw(rng, args.batch)
        t = torch.as_tensor(rng.integers(args.t_min, args.t_max + 1, size=args.batch))
        rank_weight = args.rank_weight if step >= args.rank_start_step else 0.0
        loss, denoising = training_loss(model, reference, target, pose, t, rng, args.rank_pairs, rank_weight,
                                        args.rank_margin)
        optimizer.zero_grad(set_to_none=True)
        loss.backward()
        torch.nn.utils.clip_grad_norm_(model.parameters(), 1.0)
        for group in optimizer.param_groups:
            group["lr"] = args.lr * group["scale"] * min(1.0, (step + 1) / 200)
        optimizer.step()
        ema.step(model.parameters())
        step += 1
        losses.append(denoising.item())

        row_check = ["", "", ""]
        now = time.monotonic()
        if step % args.gap_every == 0 or now - last_check >= args.check_every_minutes * 60.0:
            predictor = ema_predictor(model, ema, config)
            gaps = loss_gaps(predictor, gap_pairs, args.seed + 3)
            if now - last_check >= args.check_every_minutes * 60.0:
                best_t = max(gaps, key=gaps.get)
                result = inversion_check(predictor, check_pairs, heldout, best_t)
                row_check = [best_t, result["acc15"], result["acc30"]]
                tqdm.write(f"step {step}: inversion check at t={best_t}: RotAcc@15 {result['acc15']:.0%}, "
                           f"@30 {result['acc30']:.0%}")
                last_check = time.monotonic()
            writer.writerow([step, round((time.monotonic() - started) / 60, 2), round(float(np.mean(losses)), 5)]
                            + [round(gaps[t], 4) for t in GAP_TIMESTEPS] + row_check)
            curve.flush()
            losses = []
            model.train()
        best = max(gaps.items(), key=lambda item: item[1]) if gaps else (0, 0.0)
        bar.set_postfix(step=step, loss=f"{losses[-1] if losses else 0:.4f}", gap=f"{best[1]:+.1%}@t{best[0]}")
        bar.update(int(time.monotonic() - started) - bar.n)
        if time.monotonic() - last_checkpoint >= args.checkpoint_every_minutes * 60.0:
            save_checkpoint(checkpoint_path, model, optimizer, ema, step, time.monotonic() - started, history)
            last_checkpoint = time.monotonic()
    bar.close()
    elapsed = time.monotonic() - started
    save_checkpoint(checkpoint_path, model, optimizer, ema, step, elapsed, history)
    predictor = ema_predictor(model, ema, config)
    gaps = loss_gaps(predictor, gap_pairs, args.seed + 3)
    best_t = max(gaps, key=gaps.get)
    final = inversion_check(predictor, check_pairs, heldout, best_t)
    print(f"final: step {step}, {elapsed / 60:.1f} min, gaps {gaps}, check at t={best_t}: {final}")
    predictor.model.save_pretrained(args.out)
    (args.out / "solver_defaults.json").write_text(json.dumps(
        {"probe_t": best_t / config.num_train_timesteps,
         "refine_t_range": [best_t / config.num_train_timesteps, (best_t + 10) / config.num_train_timesteps]},
        indent=2) + "\n")
    (args.out / "training.json").write_text(json.dumps({
        "script": "scripts/train_demo_model.py",
        "seed": args.seed,
        "phases": history,
        "config": asdict(config),
        "data": {"objects": list(train.names), "train_views_per_object": train.views_per_object,
                 "heldout_views_per_object": heldout.views_per_object, "image_size": args.image_size,
                 "polar_deg": [30, 150], "fov_deg": 60},
        "steps": step, "batch": args.batch, "wall_minutes": round(elapsed / 60, 1),
        "threads": args.threads, "loss_gap_by_t": gaps, "final_check": {"t": best_t, **final,
        "pairs": len(check_pairs.pose), "grid": f"{CHECK_AZIMUTHS} azimuths x polar offsets {CHECK_POLARS_DEG}"},
    }, indent=2) + "\n")
    print(f"wrote {args.out}")


def save_checkpoint(path: Path, model: DemoDiffusionModel, optimizer: torch.optim.Optimizer, ema: EMAModel,
                    step: int, elapsed: float, history: list[dict]) -> None:
    """Atomically write everything needed to resume (``history``: the arguments of every resumed phase)."""
    temporary = path.with_suffix(".tmp")
    torch.save({"model": model.state_dict(), "optimizer": optimizer.state_dict(), "ema": ema.state_dict(),
                "step": step, "elapsed": elapsed, "history": json.dumps(history)}, temporary)
    temporary.replace(path)


if __name__ == "__main__":
    main()
