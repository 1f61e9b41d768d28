"""``SolverContext``: the one place the solver talks to the predictor, batched, counted, cancellable."""
from __future__ import annotations

import math
import threading
from collections.abc import Callable

import torch

from idpose_core.cancellation import raise_if_cancelled
from idpose_core.noise_predictor import NoisePredictor, Views
from idpose_core.solver.config import SolverConfig
from idpose_core.spherical import invert

# progress(stage, done, total): samples of the current stage evaluated so far, and its total.
Progress = Callable[[str, int, int], None]
# samples(evaluated, differentiated): the predictor samples of the whole estimate so far, after every model call.
SampleCount = Callable[[int, int], None]



def diffusion_step(fraction: float, steps: int) -> int:
    """A timestep given as a fraction of the schedule (``probe_t``, ``refine_t_range``) -> the model's step index
    among ``steps``, the last at most."""
    return min(int(round(fraction * steps)), steps - 1)

class SolverContext:
    """Predictor, encoded views, seeded randomness, sample counters, progress and cancellation.

    Probes use one fixed noise batch (``probe_batch`` draws at ``probe_t``) so that errors of
    different candidates compare fairly; gradient steps draw fresh noise and a fresh timestep.
    Progress is reported per stage in predictor samples: ``progress(stage, done, total)``.
    """

    def __init__(self, predictor: NoisePredictor, views: Views, config: SolverConfig,
                 progress: Progress | None = None, cancel: threading.Event | None = None,
                 known_polar: torch.Tensor | None = None, samples: SampleCount | None = None):
        self.predictor = predictor
        self.views = views
        self.config = config
        # (N-1,) relative polar angles known from gravity, NaN where unknown
        self.known_polar = torch.full((len(views) - 1,), math.nan) if known_polar is None else known_polar
        self.device = views.latents.device
        self.dtype = views.latents.dtype
        self.generator = torch.Generator(device="cpu").manual_seed(config.seed)
        steps = predictor.num_train_timesteps
        self.probe_t = diffusion_step(config.probe_t, steps)
        self.refine_t = tuple(diffusion_step(fraction, steps) for fraction in config.refine_t_range)
        self.probe_noise = self.draw_noise(config.probe_batch)
        self.stage_samples: dict[str, list[int]] = {}  # stage -> [evaluated, differentiated]
        self._progress = progress
        self._samples = samples
        self._cancel = cancel
        self._stage, self._done, self._total = "", 0, 0

    # ----- bookkeeping ---------------------------------------------------------------------------

    @property
    def forward_samples(self) -> int:
        """Predictor samples evaluated so far, over all stages."""
        return sum(evaluated for evaluated, _ in self.stage_samples.values())

    @property
    def backward_samples(self) -> int:
        """Predictor samples differentiated so far, over all stages."""
        return sum(differentiated for _, differentiated in self.stage_samples.values())

    @property
    def stage(self) -> str:
        """The stage being computed ("setup" before the first one)."""
        return self._stage or "setup"

    def begin_stage(self, stage: str, total: int) -> None:
        """Start counting progress of ``stage`` towards ``total`` samples."""
        self._stage, self._done, self._total = stage, 0, int(total)
        self._report()

    def _advance(self, samples: int) -> None:
        self._done += samples
        self._report()

    def _count_samples(self) -> None:
        if self._samples is not None:
            self._samples(self.forward_samples, self.backward_samples)

    def _report(self) -> None:
        if self._progress is not None:
            self._progress(self._stage, self._done, self._total)

    def hold_known_polar(self, pose: torch.Tensor, views: torch.Tensor) -> None:
        """Zero the polar gradient of the rows of ``pose`` (K, 3) whose view (K,) has a known polar angle,
        when ``known_polar`` is "fixed" (call between backward and the optimiser step)."""
        if self.config.known_polar == "fixed" and pose.grad is not None:
            held = torch.isfinite(self.known_polar[views.cpu() - 1]).to(pose.grad.device)
            pose.grad[:, 0] = torch.where(held, torch.zeros_like(pose.grad[:, 0]), pose.grad[:, 0])

    def check_cancel(self) -> None:
        """Raise ``Cancelled`` when the caller's event is set."""
        raise_if_cancelled(self._cancel, self.stage)

    def draw_noise(self, count: int) -> torch.Tensor:
        """Seeded standard normal noise (count, C, h, w) on the views' device and dtype."""
        noise = torch.randn((count, *self.views.noise_shape), generator=self.generator)
        return noise.to(device=self.device, dtype=self.dtype)

    def uniform(self, count: int) -> torch.Tensor:
        """Seeded uniform draws in [0, 1), (count,) on the CPU."""
        return torch.rand(count, generator=self.generator)

    def _errors(self, ref: torch.Tensor, tgt: torch.Tensor, pose: torch.Tensor, t: torch.Tensor,
                noise: torch.Tensor) -> torch.Tensor:
        """``noise_error`` over any number of samples in chunks of ``max_batch``; (B,)."""
        parts = []
        for start in range(0, len(ref), self.config.max_batch):
            self.check_cancel()
            chunk = slice(start, start + self.config.max_batch)
            parts.append(self.predictor.noise_error(self.views, ref[chunk].to(self.device), tgt[chunk].to(self.device),
                                                    pose[chunk], t[chunk].to(self.device), noise[chunk]))
            self.stage_samples.setdefault(self._stage, [0, 0])[0] += len(parts[-1])
            self._count_samples()
            self._advance(len(parts[-1]))
        return torch.cat(parts)

    # ----- the two kinds of evaluation ----------------------------------------------------------

    def pairwise_errors(self, ref: torch.Tensor, tgt: torch.Tensor, poses: torch.Tensor) -> torch.Tensor:
        """Probe pairwise errors ``l(p; ref, tgt) + l(p'; tgt, ref)`` under the fixed noise; (K,).

        ``ref``, ``tgt`` (K,) view indices, ``poses`` (K, 3) from ref to tgt. Each direction is the
        mean over the ``probe_batch`` noises at ``probe_t``; all K x 2 x probe_batch samples go
        through the predictor in as few calls as ``max_batch`` allows.
        """
        count, batch = len(ref), self.config.probe_batch
        if count == 0:
            return torch.zeros(0)
        poses = poses.to(device=self.device, dtype=torch.float32)
        both_ref = torch.stack([ref, tgt], dim=1)  # (K, 2): forward, reverse
        both_tgt = torch.stack([tgt, ref], dim=1)
        both_pose = torch.stack([poses, invert(poses)], dim=1)  # (K, 2, 3)
        sample_ref = both_ref[:, :, None].expand(count, 2, batch).reshape(-1)
        sample_tgt = both_tgt[:, :, None].expand(count, 2, batch).reshape(-1)
        sample_pose = both_pose[:, :, None].expand(count, 2, batch, 3).reshape(-1, 3)
        noise = self.probe_noise[None, None].expand(count, 2, *self.probe_noise.shape).reshape(
            -1, *self.probe_noise.shape[1:])
        t = torch.full((len(sample_ref),), self.probe_t, dtype=torch.long)
        with torch.no_grad():
            errors = self._errors(sample_ref, sample_tgt, sample_pose, t, noise)
        return errors.view(count, 2, batch).mean(dim=2).sum(dim=1).float().cpu()

    def gradient_step(self, ref: torch.Tensor, tgt: torch.Tensor, poses: torch.Tensor,
                      t: torch.Tensor | None = None, noise: torch.Tensor | None = None) -> torch.Tensor:
        """Errors (K,) of one gradient step, back-propagated into the leaves ``poses`` (K, 3) comes from.

        Fresh noise and t uniform in ``refine_t_range`` unless given (``t`` (K,) training steps, ``noise``
        (K, C, h, w)). Forward and backward run per ``grad_batch`` chunk and the gradients accumulate (the
        loss is a sum), so only one chunk's activations are alive at a time. Returns the errors detached.
        """
        if t is None:
            low, high = self.refine_t
            t = torch.randint(low, high + 1, (len(ref),), generator=self.generator)
        noise = self.draw_noise(len(ref)) if noise is None else noise
        size = self.config.grad_batch
        parts = []
        for start in range(0, len(ref), size):
            chunk = slice(start, start + size)
            errors = self._errors(ref[chunk], tgt[chunk], poses[chunk], t[chunk], noise[chunk])
            errors.sum().backward(retain_graph=start + size < len(ref))  # ``poses`` may share a graph
            parts.append(errors.detach())
            del errors
        self.stage_samples.setdefault(self._stage, [0, 0])[1] += len(ref)
        self._count_samples()
        return torch.cat(parts)
