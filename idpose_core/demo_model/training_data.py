"""Training and evaluation data of the demo model: pybullet renders of an object set, and view pairs.

Views are rendered once per object from random cameras (``random_camera_spheres``, fixed radius,
60 deg FOV) and cached as ``.npz``. A pair (reference, target) of the same object goes through the
pipeline's own ``preprocess_views`` (one window for the pair, white background, 256 px) and the
model's ``downsample``, exactly what the model sees at inference, with the window scale jittered. For robot
scenes (``RobotCrops``) a pair is drawn from renders of its cameras under one of the object's random lamps and
goes through ``robot_crop``'s augmentation first.
"""
from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import numpy as np
import torch
from tqdm import tqdm

from idpose_core.demo_model.robot_crops import CropAugmentation, Tone, random_tone, robot_crop
from idpose_core.preprocessing import WINDOW_SCALE, PreprocessingError, check_object_mask, preprocess_views
from idpose_core.spherical import relative
from idpose_core.synthetic.scenes import (
    CAMERA_POLAR_DEG,
    ObjectSpec,
    SceneRenderer,
    random_camera_spheres,
    random_light,
)
from idpose_core.view_input import ViewInput


@dataclass(frozen=True)
class RenderedViews:
    """Renders of O objects from V cameras each: ``rgb`` (O, V, S, S, 3) uint8 on white, ``mask``
    (O, V, S, S) bool, ``cameras`` (O, V, 3) absolute (polar, azimuth, radius), ``names`` (O,)."""

    rgb: np.ndarray
    mask: np.ndarray
    cameras: np.ndarray
    names: tuple[str, ...]

    @property
    def num_objects(self) -> int:
        return int(self.rgb.shape[0])

    @property
    def views_per_object(self) -> int:
        return int(self.rgb.shape[1])

    @cached_property
    def usable(self) -> np.ndarray:
        """(O, V) bool: the views whose mask the pipeline accepts (``check_object_mask``); a thin object seen
        end-on in a small render can fall under the pipeline's smallest object size."""
        usable = np.ones(self.mask.shape[:2], bool)
        for o, v in np.ndindex(*usable.shape):
            try:
                check_object_mask(self.mask[o, v], "render")
            except PreprocessingError:
                usable[o, v] = False
        return usable


def render_views(specs: Sequence[ObjectSpec], views_per_object: int, image_size: int, seed: int,
                 polar_deg: tuple[float, float] = CAMERA_POLAR_DEG) -> RenderedViews:
    """Render every object from its own ``views_per_object`` random cameras (seeded per object)."""
    rng = np.random.default_rng(seed)
    rgbs, masks, cameras = [], [], []
    for spec in tqdm(specs, desc=f"render {views_per_object} views/object", unit="object"):
        sph = random_camera_spheres(rng, views_per_object, polar_deg=polar_deg)
        with SceneRenderer(spec, image_size) as renderer:
            frames = [renderer.render(*camera) for camera in sph]
        rgbs.append(np.stack([f[0] for f in frames]))
        masks.append(np.stack([f[1] for f in frames]))
        cameras.append(sph)
    return RenderedViews(np.stack(rgbs), np.stack(masks), np.stack(cameras), tuple(s.name for s in specs))


def cached_views(cache: Path, specs: Sequence[ObjectSpec], views_per_object: int, image_size: int,
                 seed: int) -> RenderedViews:
    """``render_views`` memoised in an ``.npz`` file keyed by the object names and arguments."""
    cache = Path(cache)
    if cache.is_file():
        data = np.load(cache)
        names = tuple(str(n) for n in data["names"])
        if names == tuple(s.name for s in specs) and data["rgb"].shape[1:3] == (views_per_object, image_size):
            return RenderedViews(data["rgb"], data["mask"], data["cameras"], names)
    views = render_views(specs, views_per_object, image_size, seed)
    cache.parent.mkdir(parents=True, exist_ok=True)
    np.savez(cache, rgb=views.rgb, mask=views.mask, cameras=views.cameras, names=np.array(views.names))
    return views


LIT_ELEVATION_DEG = (10.0, 85.0)  # lamps from near the horizon to overhead
LIT_AMBIENT = (0.3, 0.7)
LIT_DIFFUSE = (0.3, 0.7)


def render_lit(specs: Sequence[ObjectSpec], cameras: np.ndarray, image_size: int, seed: int, lights: int
               ) -> np.ndarray:
    """Each object's cameras (O, V, 3) rendered again under ``lights`` random lamps with shadows, each lamp
    fixed in the object's world as in a room: (O, V, lights, S, S, 3) uint8 (the masks are the clean renders')."""
    rng = np.random.default_rng(seed)
    out = np.empty((*cameras.shape[:2], lights, image_size, image_size, 3), np.uint8)
    for o, spec in enumerate(tqdm(specs, desc=f"render under {lights} lamps/object", unit="object")):
        lamps = [random_light(rng, LIT_ELEVATION_DEG, LIT_AMBIENT, LIT_DIFFUSE) for _ in range(lights)]
        with SceneRenderer(spec, image_size) as renderer:
            for v, camera in enumerate(cameras[o]):
                for k, lamp in enumerate(lamps):
                    out[o, v, k] = renderer.render(*camera, light=lamp)[0]
    return out


def cached_lit(cache: Path, specs: Sequence[ObjectSpec], views: RenderedViews, seed: int, lights: int
               ) -> np.ndarray:
    """``render_lit`` of ``views``' cameras memoised in an ``.npz`` file."""
    cache = Path(cache)
    expected = (*views.cameras.shape[:2], lights, *views.rgb.shape[2:])
    if cache.is_file():
        lit = np.load(cache)["rgb"]
        if lit.shape == expected:
            return lit
    lit = render_lit(specs, views.cameras, views.rgb.shape[2], seed, lights)
    cache.parent.mkdir(parents=True, exist_ok=True)
    np.savez(cache, rgb=lit)
    return lit


TARGET_AUGMENTATION = CropAugmentation(scale=0.0, shadow=0.0, occluder=0.0, rim=0.0, border=0.0)
"""The target of a training pair keeps its geometry (the model predicts it: what it cannot know from the
reference and the pose, such as an occluder, would teach it to ignore the pose); it shares the camera's
tone and lamp, and is blurred and noisy like the reference."""


@dataclass(frozen=True)
class RobotCrops:
    """Pairs as a robot's crops: both views under the clean light or one of the object's ``lit`` lamps
    (O, V, L, S, S, 3) with equal odds (``other_lamp``: the target under another one), one camera tone, then
    ``robot_crop`` with ``reference`` and ``target`` augmentation (the unaugmented view where that leaves an
    object the pipeline would refuse, e.g. too small)."""

    lit: np.ndarray
    reference: CropAugmentation = CropAugmentation()
    target: CropAugmentation = TARGET_AUGMENTATION
    other_lamp: float = 0.1

    def pair(self, views: RenderedViews, o: int, a: int, b: int, rng: np.random.Generator
             ) -> list[tuple[np.ndarray, np.ndarray]]:
        """(rgb, mask) of views ``a`` (reference) and ``b`` (target) of object ``o``, as one robot saw them."""
        tone = random_tone(rng)
        lamp = int(rng.integers(self.lit.shape[2] + 1))
        target_lamp = int(rng.integers(self.lit.shape[2] + 1)) if rng.random() < self.other_lamp else lamp
        return [self.view(views, o, a, lamp, self.reference, tone, rng),
                self.view(views, o, b, target_lamp, self.target, tone, rng)]

    def view(self, views: RenderedViews, o: int, k: int, lamp: int, augmentation: CropAugmentation, tone: Tone,
             rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        """(rgb, mask) of view ``k`` of object ``o`` under ``lamp`` (0: the clean light) and the camera's ``tone``."""
        rgb = views.rgb[o, k] if lamp == 0 else self.lit[o, k, lamp - 1]
        crop, mask = robot_crop(rgb, views.mask[o, k], rng, augmentation, tone)
        try:
            check_object_mask(mask, "augmented")
        except PreprocessingError:
            return rgb, views.mask[o, k]
        return crop, mask


@dataclass(frozen=True)
class PairBatch:
    """B view pairs: ``reference``/``target`` (B, 3, r, r) in [-1, 1], true relative ``pose`` (B, 3)
    reference -> target, and the indices (object, reference view, target view) each (B,)."""

    reference: torch.Tensor
    target: torch.Tensor
    pose: torch.Tensor
    object_index: np.ndarray
    reference_index: np.ndarray
    target_index: np.ndarray


def make_pairs(views: RenderedViews, object_index: np.ndarray, reference_index: np.ndarray,
               target_index: np.ndarray, downsample: Callable[[torch.Tensor], torch.Tensor],
               window_scales: np.ndarray | float = WINDOW_SCALE, crops: RobotCrops | None = None,
               rng: np.random.Generator | None = None, robot: np.ndarray | None = None) -> PairBatch:
    """Preprocess each pair as a two-view set (``preprocess_views``) and downsample to model size; with
    ``crops``, the pairs that ``robot`` (bool per pair, default all) marks are first made a robot's crops
    (drawn from ``rng``)."""
    scales = np.broadcast_to(np.asarray(window_scales, dtype=np.float64), object_index.shape)
    robot = np.broadcast_to(np.ones(1, bool) if robot is None else np.asarray(robot, bool), object_index.shape)
    if crops is not None and rng is None:
        raise ValueError("robot crops need a random generator")
    images = []
    for o, a, b, scale, as_robot in zip(object_index, reference_index, target_index, scales, robot):
        if crops is None or not as_robot:
            pair = [ViewInput(views.rgb[o, k], views.mask[o, k].astype(np.uint8) * 255) for k in (a, b)]
        else:
            pair = [ViewInput(rgb, mask.astype(np.uint8) * 255) for rgb, mask in crops.pair(views, o, a, b, rng)]
        images.append(preprocess_views(pair, window_scale=float(scale)).images)
    small = downsample(torch.cat(images))
    small = small.reshape(len(images), 2, *small.shape[1:])
    pose = relative(views.cameras[object_index, reference_index], views.cameras[object_index, target_index])
    return PairBatch(small[:, 0], small[:, 1], torch.as_tensor(pose, dtype=torch.float32), object_index,
                     reference_index, target_index)


def random_pairs(views: RenderedViews, rng: np.random.Generator, count: int) -> tuple[np.ndarray, ...]:
    """``count`` random (object, reference view, target view) index triples with distinct usable views (objects
    with fewer than two usable views are never drawn)."""
    candidates = np.flatnonzero(views.usable.sum(1) >= 2)
    if not len(candidates):
        raise ValueError("no object has two views the pipeline accepts")
    objects = rng.choice(candidates, size=count)
    reference, target = np.empty(count, int), np.empty(count, int)
    for k, o in enumerate(objects):
        reference[k], target[k] = rng.choice(np.flatnonzero(views.usable[o]), size=2, replace=False)
    return objects, reference, target


@dataclass(frozen=True)
class PairSource:
    """Renders that training pairs are drawn from: ``views``, their robot-crop renders (``crops``, or None for
    clean pairs only) and the source's ``weight`` among the pool's sources."""

    views: RenderedViews
    crops: RobotCrops | None = None
    weight: float = 1.0


class PairPool:
    """A rolling pool of preprocessed training pairs: each draw adds ``refresh`` fresh pairs, each from one of the
    ``sources`` (odds by weight) and each of them a robot's crops with odds ``robot_share`` (where the source has
    crops), else the clean renders.

    Preprocessing a pair costs about as much as a tenth of a training step here, so pairs are
    reused a few times instead of being prepared anew for every batch.
    """

    FIELDS = ("reference", "target", "pose")

    def __init__(self, sources: Sequence[PairSource], downsample: Callable[[torch.Tensor], torch.Tensor],
                 capacity: int, refresh: int, window_scale_range: tuple[float, float], robot_share: float = 1.0):
        if not sources:
            raise ValueError("a pair pool needs at least one source")
        weights = np.array([source.weight for source in sources], dtype=np.float64)
        if (weights < 0).any() or weights.sum() <= 0:
            raise ValueError(f"source weights must be >= 0 with a positive sum, got {weights.tolist()}")
        self.sources, self.odds = list(sources), weights / weights.sum()
        self.downsample, self.robot_share = downsample, robot_share
        self.capacity, self.refresh, self.window_scale_range = capacity, refresh, window_scale_range
        self.tensors: dict[str, torch.Tensor] = {}

    def _fresh(self, rng: np.random.Generator, count: int) -> dict[str, torch.Tensor]:
        counts = rng.multinomial(count, self.odds)
        parts = []
        for source, share in zip(self.sources, counts):
            if not share:
                continue
            scales = rng.uniform(*self.window_scale_range, size=share)
            robot = rng.random(share) < self.robot_share
            parts.append(make_pairs(source.views, *random_pairs(source.views, rng, share), self.downsample, scales,
                                    source.crops, rng, robot))
        return {name: torch.cat([getattr(batch, name) for batch in parts]) for name in self.FIELDS}

    def fill(self, rng: np.random.Generator, count: int) -> None:
        """Start the pool with ``count`` pairs."""
        self.tensors = self._fresh(rng, count)

    def draw(self, rng: np.random.Generator, batch: int) -> tuple[torch.Tensor, ...]:
        """Add ``refresh`` fresh pairs (replacing random ones once full), then sample ``batch`` pairs:
        (reference, target, pose)."""
        if not self.tensors:
            raise RuntimeError("fill the pool before drawing from it")
        fresh = self._fresh(rng, self.refresh)
        size = len(self.tensors["pose"])
        if size < self.capacity:
            self.tensors = {name: torch.cat([self.tensors[name], fresh[name]]) for name in self.FIELDS}
        else:
            slots = torch.as_tensor(rng.choice(size, size=self.refresh, replace=False))
            for name in self.FIELDS:
                self.tensors[name][slots] = fresh[name]
        chosen = torch.as_tensor(rng.choice(len(self.tensors["pose"]), size=batch, replace=False))
        return tuple(self.tensors[name][chosen] for name in self.FIELDS)
