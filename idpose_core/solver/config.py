"""``SolverConfig``: every tunable of the ID-Pose solver, with the paper's defaults and presets."""
from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, fields
from typing import Any

import numpy as np

VARIANTS = ("full", "tr", "naive")
KNOWN_POLAR_MODES = ("fixed", "start")
SEARCHES = ("grid", "starts")
DEFAULT_POLAR_CANDIDATES_DEG = (-120.0, -60.0, 0.0, 60.0, 120.0)
ANCHOR_POLAR_STEP_DEG = 45.0


@dataclass(frozen=True, init=False)
class SolverConfig:
    """Solver settings; defaults are the official implementation's (Zero-1-to-3 XL, one GPU).

    Built from keyword arguments only; ``chosen`` remembers which settings the caller gave (a
    preset's included), so that a model's recommendations (``with_recommended``) never replace
    them, even where a chosen value equals the paper's default. Derive variants with ``updated``.

    ``variant``: "naive" (pairs independent), "tr" (triangular refinement), "full" (triangular
    exploration and refinement). Timesteps are fractions of the predictor's training steps.
    Learning rates suit Zero-1-to-3's noise error; a predictor with a steeper error (e.g. the render
    oracle) needs smaller ones. ``runner_up_steps`` (per view) polish each view's runner-up candidate
    before ``ambiguity_deg``/``ambiguity_margin`` decide whether the view is flagged ambiguous (see
    ``idpose_core.solver.scoring``). ``max_batch`` bounds the samples of one predictor call;
    ``grad_batch`` the samples differentiated together (a gradient step over more, e.g. the adjust
    steps of all candidates, runs forward and backward chunk by chunk, so activation memory stays
    that of one chunk: full-size Zero-1-to-3 holds about 0.45 GB per float32 sample). ``known_polar``
    says what happens to a view's relative polar angle when gravity gives it (``estimate_poses``'s
    ``known_polar``): "fixed" explores and refines azimuth and radius only, "start" explores at the known
    polar angle and lets refinement move it.

    ``search`` says how start poses are found: "grid" (ID-Pose: probe a candidate grid, adjust the
    better ``adjust_top`` of them, keep the best) or "starts" (iFusion: Adam from each of
    ``start_azimuths_deg`` for ``start_steps`` steps, both directions in one batch, the timestep annealed
    linearly over ``start_t_range``; the start with the smallest summed loss wins;
    ``idpose_core.solver.starts``). ``refine_stop_deg`` / ``refine_stop_steps`` end refinement early
    once no pose moved more than that angle over that many steps (0 = never); ``runner_up_gate`` polishes
    the runner-ups only when some view's best far candidate probes within that share of the error
    spread of its answer (None = always).

    ``azimuth_refinements`` narrows the grid coarse to fine before any adjust step: that many times, each
    view's best ``keep_top`` candidates are probed again at half the last azimuth spacing on either side
    (forward samples only). ``gravity_fallback`` names the preset that runs instead when no view's polar
    angle is known (a schedule made for gravity; ``fallback``).
    """

    variant: str = "full"
    azimuth_candidates: int = 8
    polar_candidates_deg: tuple[float, ...] | None = None
    anchor_polar_deg: float | None = None
    probe_batch: int = 16
    probe_t: float = 0.2
    adjust_steps: int = 10
    adjust_lr: float = 10.0
    keep_top: int = 5
    refine_steps_per_view: int = 600
    refine_lr: float = 1.0
    refine_t_range: tuple[float, float] = (0.2, 0.21)
    average_last: int = 20
    max_batch: int = 64
    grad_batch: int = 8
    seed: int = 0
    runner_up_steps: int = 100
    ambiguity_deg: float = 30.0
    ambiguity_margin: float = 0.1
    known_polar: str = "fixed"
    adjust_top: int | None = None
    refine_stop_deg: float = 0.0
    refine_stop_steps: int = 0
    runner_up_gate: float | None = None
    search: str = "grid"
    start_azimuths_deg: tuple[float, ...] = (0.0, 90.0, 180.0, -90.0)
    start_steps: int = 100
    start_lr: float = 0.1
    start_lr_factor: float = 0.6
    start_lr_patience: int = 10
    start_t_range: tuple[float, float] = (1.0, 0.0)
    start_radius_range: float = 0.8
    azimuth_refinements: int = 0
    gravity_fallback: str | None = None

    def __init__(self, **settings: Any) -> None:
        defaults = {f.name: f.default for f in fields(self)}
        unknown = sorted(set(settings) - set(defaults))
        if unknown:
            raise TypeError(f"SolverConfig has no settings {unknown}; it has {sorted(defaults)}")
        for name, default in defaults.items():
            object.__setattr__(self, name, settings.get(name, default))
        object.__setattr__(self, "_chosen", frozenset(settings))

    @property
    def chosen(self) -> frozenset[str]:
        """The settings given by the caller rather than left at their defaults."""
        return self._chosen

    def updated(self, **changes: Any) -> SolverConfig:
        """A copy with ``changes`` applied; they join the chosen settings."""
        return SolverConfig(**{**{name: getattr(self, name) for name in self.chosen}, **changes})

    @classmethod
    def preset(cls, name: str, **overrides) -> SolverConfig:
        """Named settings (``PRESETS``), then overrides; all of them count as chosen.

        "default": the paper's. "fast": the paper's grid probed with 2 noises, the best 4 candidates adjusted,
        3 kept, 50 refinement steps per view, the runner-up polished only when it probes close
        (``bench/README.md``, the frontier).
        "live": for gravity (every view's elevation known): 12 azimuths probed with one noise (both
        directions), narrowed twice coarse to fine (15 and 7.5 deg), the best 2 kept, at most 16 refinement
        steps per view (stopping once no pose moved 0.5 deg over 6 steps; the answer the mean of the last 6),
        the runner-up polished only when it probes close; without gravity it runs "fast" (``gravity_fallback``).
        "ifusion": iFusion's pose search (chinhsuanwu/ifusion, ``optimize_pose_loop``, ``config/main.yaml``):
        4 starts at azimuth 0, 90, 180, -90 deg, 100 Adam steps each at lr 0.1 with plateau decay (factor
        0.6, patience 10), both directions per step, the timestep annealed from 1000 to 0; each view against
        the anchor ("naive"; ``variant="tr"`` with ``refine_steps_per_view`` adds triangular refinement).
        """
        if name not in PRESETS:
            raise ValueError(f"unknown solver preset {name!r}; choose one of {sorted(PRESETS)}")
        config = cls(**{**PRESETS[name], **overrides})
        config.validate()
        return config

    def with_recommended(self, recommended: Mapping[str, Any]) -> SolverConfig:
        """These settings with a predictor's recommendations (its ``solver_defaults``, e.g. the noise
        levels a small model was trained at) in every setting the caller did not choose."""
        unknown = sorted(set(recommended) - {f.name for f in fields(self)})
        if unknown:
            raise ValueError(f"recommended solver settings name unknown SolverConfig fields {unknown}")
        config = self.updated(**{name: value for name, value in recommended.items() if name not in self.chosen})
        config.validate()
        return config

    def validate(self) -> None:
        """Raise ``ValueError`` naming the first field out of range."""
        def need(ok: bool, field: str, rule: str) -> None:
            if not ok:
                raise ValueError(f"SolverConfig.{field} = {getattr(self, field)!r}: must be {rule}")

        need(self.variant in VARIANTS, "variant", f"one of {VARIANTS}")
        need(self.known_polar in KNOWN_POLAR_MODES, "known_polar", f"one of {KNOWN_POLAR_MODES}")
        need(self.search in SEARCHES, "search", f"one of {SEARCHES}")
        for name in ("azimuth_candidates", "probe_batch", "keep_top", "average_last", "max_batch",
                     "grad_batch", "start_steps"):
            need(isinstance(getattr(self, name), int) and getattr(self, name) >= 1, name, "an integer >= 1")
        for name in ("adjust_steps", "refine_steps_per_view", "runner_up_steps", "seed", "refine_stop_steps",
                     "start_lr_patience", "azimuth_refinements"):
            need(isinstance(getattr(self, name), int) and getattr(self, name) >= 0, name, "an integer >= 0")
        for name in ("adjust_lr", "refine_lr", "ambiguity_deg", "ambiguity_margin", "start_lr",
                     "start_radius_range"):
            value = getattr(self, name)
            need(isinstance(value, (int, float)) and math.isfinite(value) and value > 0, name, "a finite number > 0")
        need(isinstance(self.refine_stop_deg, (int, float)) and 0.0 <= self.refine_stop_deg < math.inf,
             "refine_stop_deg", "a finite number >= 0")
        need(self.gravity_fallback is None or (self.gravity_fallback in PRESETS
                                               and not PRESETS[self.gravity_fallback].get("gravity_fallback")),
             "gravity_fallback", f"None or a preset without a fallback of its own, one of {sorted(PRESETS)}")
        need(0.0 < self.start_lr_factor < 1.0, "start_lr_factor", "in (0, 1)")
        need(self.adjust_top is None or (isinstance(self.adjust_top, int) and self.adjust_top >= 1), "adjust_top",
             "None (the better half) or an integer >= 1")
        gate = self.runner_up_gate
        need(gate is None or (isinstance(gate, (int, float)) and gate >= 0), "runner_up_gate",
             "None (always polish) or a number >= 0")
        need(0.0 <= self.probe_t < 1.0, "probe_t", "in [0, 1)")
        low, high = self.refine_t_range
        need(0.0 <= low <= high < 1.0, "refine_t_range", "(low, high) with 0 <= low <= high < 1")
        first, last = self.start_t_range
        need(0.0 <= first <= 1.0 and 0.0 <= last <= 1.0, "start_t_range", "(first, last) fractions in [0, 1]")
        need(len(self.start_azimuths_deg) > 0 and all(math.isfinite(a) for a in self.start_azimuths_deg),
             "start_azimuths_deg", "a non-empty tuple of finite angles")
        if self.polar_candidates_deg is not None:
            need(len(self.polar_candidates_deg) > 0
                 and all(math.isfinite(a) and -180.0 <= a <= 180.0 for a in self.polar_candidates_deg),
                 "polar_candidates_deg", "a non-empty tuple of angles in [-180, 180]")
        if self.anchor_polar_deg is not None:
            need(math.isfinite(self.anchor_polar_deg) and 0.0 < self.anchor_polar_deg < 180.0,
                 "anchor_polar_deg", "in (0, 180)")

    def fallback(self) -> SolverConfig:
        """The ``gravity_fallback`` preset with this config's chosen settings that do not shape the schedule
        (``SCHEDULE_NEUTRAL``: timesteps, rates, seed, batching, the ambiguity rule, the anchor's polar angle)."""
        if self.gravity_fallback is None:
            raise ValueError("this solver config names no gravity_fallback preset")
        kept = {name: getattr(self, name) for name in self.chosen & SCHEDULE_NEUTRAL}
        return SolverConfig.preset(self.gravity_fallback, **kept)

    def polar_candidates(self) -> np.ndarray:
        """Relative polar candidates (P,) radians: given, derived from the anchor's, or the default.

        From an anchor polar angle q: 0 and steps of 45 deg up and down while q + d stays in (0, 180).
        """
        if self.polar_candidates_deg is not None:
            return np.radians(np.asarray(self.polar_candidates_deg, dtype=np.float64))
        if self.anchor_polar_deg is not None:
            q = self.anchor_polar_deg
            up = np.arange(0.0, -q, -ANCHOR_POLAR_STEP_DEG)
            down = np.arange(ANCHOR_POLAR_STEP_DEG, 180.0 - q, ANCHOR_POLAR_STEP_DEG)
            return np.radians(np.concatenate([up, down]))
        return np.radians(np.asarray(DEFAULT_POLAR_CANDIDATES_DEG))

    def as_dict(self) -> dict:
        """Plain dict of every field (for logs and result files)."""
        return {f.name: getattr(self, f.name) for f in fields(self)}


# Named settings of ``SolverConfig.preset``; the evidence for each is in ``bench/README.md``.
PRESETS: dict[str, dict[str, Any]] = {
    "default": {},
    "fast": dict(probe_batch=2, adjust_top=4, keep_top=3, refine_steps_per_view=50, runner_up_steps=20,
                 runner_up_gate=0.3),
    "live": dict(azimuth_candidates=12, probe_batch=1, adjust_steps=0, azimuth_refinements=2, keep_top=2,
                 refine_steps_per_view=16, refine_stop_deg=0.5, refine_stop_steps=6, average_last=6,
                 runner_up_steps=8, runner_up_gate=0.3, gravity_fallback="fast"),
    "ifusion": dict(search="starts", variant="naive", probe_batch=4, refine_steps_per_view=0, runner_up_steps=0),
}
# The settings a fallback keeps from the config it replaces: they tune the model or the output, not the schedule.
SCHEDULE_NEUTRAL = frozenset({
    "variant", "anchor_polar_deg", "polar_candidates_deg", "probe_t", "adjust_lr", "refine_lr", "refine_t_range",
    "max_batch", "grad_batch", "seed", "ambiguity_deg", "ambiguity_margin", "known_polar", "start_lr",
    "start_t_range", "start_radius_range"})
