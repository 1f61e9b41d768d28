"""One sitting of a training run: resume, train on a rolling pool of view pairs with an EMA of the weights while
the curve follows the held-out sets, then save the checkpoint and write the model folder."""
from __future__ import annotations

import time

import numpy as np
import torch
from diffusers.training_utils import EMAModel
from tqdm import tqdm

from idpose_core.demo_model.model import DemoDiffusionModel
from idpose_core.demo_model.training.checkpoints import (
    CHECKPOINT_FILE,
    ema_predictor,
    model_config,
    restore,
    save_checkpoint,
)
from idpose_core.demo_model.training.checks import CURVE_SETS, HeldOut, describe, probe_timestep
from idpose_core.demo_model.training.curve import CURVE_FILE, PLOT_FILE, Curve
from idpose_core.demo_model.training.data import TrainingData
from idpose_core.demo_model.training.loss import training_loss, wrong_poses
from idpose_core.demo_model.training.options import TrainingOptions
from idpose_core.demo_model.training.records import write_solver_defaults, write_training_record
from idpose_core.demo_model.training.schedules import learning_rate_factor, robot_share_at
from idpose_core.demo_model.training_data import PairPool
from idpose_core.preprocessing import WINDOW_SCALE


def optimisation_step(model: DemoDiffusionModel, optimizer: torch.optim.Optimizer, ema: EMAModel, pool: PairPool,
                      options: TrainingOptions, rng: np.random.Generator, lr: float) -> float:
    """One step at learning rate ``lr`` on a batch of the pool at random timesteps, the EMA following; returns the
    batch's denoising loss."""
    reference, target, pose = pool.draw(rng, options.batch)
    t = torch.as_tensor(rng.integers(options.t_min, options.t_max + 1, size=options.batch))
    loss, denoising = training_loss(model, reference, target, pose, wrong_poses(pose, rng), t, options.rank_weight,
                                    options.rank_margin)
    optimizer.zero_grad(set_to_none=True)
    loss.backward()
    torch.nn.utils.clip_grad_norm_(model.parameters(), 1.0)
    for group in optimizer.param_groups:
        group["lr"] = lr
    optimizer.step()
    ema.step(model.parameters())
    return denoising.item()


def train(options: TrainingOptions) -> None:
    """Train for at most ``chunk_minutes`` (or up to the budget, or ``max_steps``) from where the work dir's
    checkpoint or ``init_from`` stopped; log progress and checks, and write the checkpoint and the model folder."""
    torch.set_num_threads(options.threads)
    torch.manual_seed(options.seed)
    options.work_dir.mkdir(parents=True, exist_ok=True)
    config = model_config(options)
    model = DemoDiffusionModel(config)
    optimizer = torch.optim.AdamW(model.parameters(), lr=options.lr, weight_decay=1e-4)
    ema = EMAModel(model.parameters(), decay=options.ema_decay)
    step, elapsed, history = restore(options, model, optimizer, ema)
    history.append({"from_step": step, "arguments": options.record()})
    data = TrainingData(options)
    held_out = HeldOut(options, data, model)
    print(f"{data.catalogue.num_objects} catalogue + {data.demo.num_objects} demo objects; random poses on the "
          f"held-out check pairs: {held_out.random_baseline(options.seed)}")
    curve = Curve(options.work_dir, options.init_from)
    checkpoint_path = options.work_dir / CHECKPOINT_FILE

    budget = options.budget_seconds
    stop_at = min(budget, elapsed + options.chunk_minutes * 60.0)
    started = time.monotonic() - elapsed
    last_checkpoint = last_check = time.monotonic()
    gaps: dict[str, dict[int, float]] = {}
    losses: list[float] = []
    jitter = (WINDOW_SCALE - options.window_jitter, WINDOW_SCALE + options.window_jitter)  # around inference's
    pool = PairPool(data.sources(options.demo_share), model.downsample, options.pool, options.pool_refresh, jitter,
                    robot_share_at(elapsed / budget, options))
    pool.fill(np.random.default_rng([options.seed, step, 1]), min(512, options.pool))
    bar = tqdm(total=int(stop_at), initial=int(elapsed), unit="s", desc="train model")
    model.train()
    while True:
        elapsed = time.monotonic() - started
        if elapsed >= stop_at or (options.max_steps and step >= options.max_steps):
            break
        pool.robot_share = robot_share_at(elapsed / budget, options)
        rng = np.random.default_rng([options.seed, step])
        losses.append(optimisation_step(model, optimizer, ema, pool, options, rng,
                                        options.lr * learning_rate_factor(elapsed / budget)))
        step += 1

        check_due = time.monotonic() - last_check >= options.check_every_minutes * 60.0
        if step % options.gap_every == 0 or check_due:
            predictor = ema_predictor(model, ema, config)
            gaps = held_out.gaps(predictor)
            check_t = checks = None
            if check_due:
                check_t = probe_timestep(gaps, options.t_min, options.t_max)
                checks = held_out.checks(predictor, check_t)
                tqdm.write(f"step {step}: inversion check at t={check_t}: {describe(checks)}")
                last_check = time.monotonic()
            curve.write(step, (time.monotonic() - started) / 60, float(np.mean(losses)), gaps, check_t, checks)
            losses = []
            model.train()
        best = {name: max(by_t.values()) for name, by_t in gaps.items()}
        bar.set_postfix(step=step, loss=f"{losses[-1] if losses else 0:.4f}", robot=f"{pool.robot_share:.0%}",
                        gap="/".join(f"{best.get(name, 0.0):+.0%}" for name in CURVE_SETS))
        bar.update(int(time.monotonic() - started) - bar.n)
        if time.monotonic() - last_checkpoint >= options.checkpoint_every_minutes * 60.0:
            save_checkpoint(checkpoint_path, model, optimizer, ema, step, time.monotonic() - started, history)
            last_checkpoint = time.monotonic()
    bar.close()
    elapsed = time.monotonic() - started
    save_checkpoint(checkpoint_path, model, optimizer, ema, step, elapsed, history)
    predictor = ema_predictor(model, ema, config)
    gaps = held_out.gaps(predictor)
    best_t = probe_timestep(gaps, options.t_min, options.t_max)
    final = held_out.checks(predictor, best_t)
    print(f"step {step}, {elapsed / 60:.1f} of {options.minutes:.0f} min, gaps {gaps}, check at t={best_t}: "
          f"{describe(final)}")
    predictor.model.save_pretrained(options.out)
    write_solver_defaults(options.out, best_t, options.t_max, config)
    write_training_record(options.out, options, config, data, history, step, elapsed, gaps, best_t, final,
                          len(held_out.check["novel"].pose))
    curve.publish(options.out)
    print(f"wrote {options.out} with its {CURVE_FILE} and {PLOT_FILE}")
