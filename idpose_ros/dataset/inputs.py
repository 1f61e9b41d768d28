"""The inputs of a data-set evaluation: rosbag2 bags, flight recordings and the official ID-Pose data layout.

Every kind plans ``EstimateTask``s (the protocol's unit of work) and hand out their views decoded, as the
``ViewInput``s the estimators take, so every input goes through the same estimator code. A bag's picks are
drawn as ``evaluate_bag`` draws them; the official layout's samples JSON fixes them instead:
``{"data_root": "data/omni3d/", "samples": [{"name": <object>, "anchor_vid": 94, "target_vids": [15, 25]}]}``
with ``<data_root>/<object>/images/<vid>.png`` (RGBA, alpha = object mask) and ``poses/<vid>.npy``
(4x4 camera-to-world, OpenGL camera axes, world up +z, object at the origin). A flight recording
(``recording_input``) plans one estimate per result the node published, and gives that result too.
"""
from __future__ import annotations

import glob
import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any, Protocol

import cv2
import numpy as np

from idpose_core.evaluation.protocol import EstimateTask, EvaluationProtocol, tasks_for_picks
from idpose_core.view_input import ViewInput
from idpose_ros.dataset.recording_input import RecordingInput
from idpose_ros.evaluation.bag_evaluation import plan_bag
from idpose_ros.evaluation.bag_io import BagError
from idpose_ros.evaluation.bag_views import BagViews, load_views
from idpose_ros.evaluation.ground_truth import GroundTruthOptions, read_views, require_usable
from idpose_ros.recording.log_format import is_recording, recordings_in

PNG_TO_RGB = {1: cv2.COLOR_GRAY2RGB, 3: cv2.COLOR_BGR2RGB, 4: cv2.COLOR_BGRA2RGB}


class InputError(Exception):
    """A user-facing problem with an input of the official layout; the message says what and where."""


class DatasetInput(Protocol):
    """One object's posed views: ``name`` identifies it in results.jsonl (a resolved path), ``dataset`` is the
    group the report scores it in, ``kind`` is "bag", "recording" or "official"."""

    name: str
    dataset: str
    kind: str

    def plan(self, protocol: EvaluationProtocol) -> list[EstimateTask]:
        """The estimates of the protocol on these views, in order."""
        ...

    def views(self, view_ids: set[int]) -> tuple[dict[int, ViewInput], dict[int, str]]:
        """These views decoded, with the other inputs a bag holds; and why any of them could not be."""
        ...

    def published(self, task: EstimateTask) -> dict[str, tuple[list[dict[str, Any]], dict[str, Any]]]:
        """Answers the input itself holds for this task (a recording's published result), scored: method ->
        (pair records, row); empty for views that come without answers."""
        ...

    def summary(self) -> dict[str, Any]:
        """What the report says about the input's views."""
        ...


class BagInput:
    """A rosbag2 bag: views and ground truth as ``evaluate_bag`` reads them, picks drawn as it draws them."""

    kind = "bag"

    def __init__(self, path: Path, ground_truth: GroundTruthOptions):
        """Reads the bag's views and ground truth; BagError for an unreadable bag or too few usable views."""
        self.path, self.ground_truth = Path(path), ground_truth
        self.bag_views: BagViews = read_views(self.path, ground_truth)
        require_usable(self.bag_views, ground_truth.image_topic)
        self.name = str(self.path.resolve())
        self.dataset = self.path.resolve().parent.name

    def plan(self, protocol: EvaluationProtocol) -> list[EstimateTask]:
        return plan_bag(self.bag_views, self.ground_truth, protocol)

    def views(self, view_ids: set[int]) -> tuple[dict[int, ViewInput], dict[int, str]]:
        return load_views(self.path, self.ground_truth.image_topic, view_ids, self.bag_views, self.ground_truth.inputs)

    def published(self, task: EstimateTask) -> dict[str, tuple[list[dict[str, Any]], dict[str, Any]]]:
        return {}

    def summary(self) -> dict[str, Any]:
        views = self.bag_views
        return {"views": len(views.views), "usable": len(views.pool), "skipped": len(views.skipped)}


def numbered_files(folder: Path, suffix: str) -> dict[int, Path]:
    """``<vid><suffix>`` files of a folder by their integer view id (``015.png`` -> 15)."""
    return {int(path.stem): path for path in folder.glob(f"*{suffix}") if path.stem.isdigit()}


def read_png_view(path: Path) -> ViewInput:
    """An 8-bit PNG (grey, RGB or RGBA) as a view: its RGB and, for RGBA, its alpha as the object mask."""
    pixels = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if pixels is None or pixels.dtype != np.uint8:
        raise InputError(f"{path}: not an 8-bit image")
    channels = 1 if pixels.ndim == 2 else pixels.shape[2]
    if channels not in PNG_TO_RGB:
        raise InputError(f"{path}: {channels} channels, expected 1, 3 or 4")
    alpha = np.ascontiguousarray(pixels[..., 3]) if channels == 4 else None
    return ViewInput(cv2.cvtColor(pixels, PNG_TO_RGB[channels]), alpha)


class OfficialInput:
    """One object of the official layout with the samples (anchor + targets) the samples JSON names for it."""

    kind = "official"

    def __init__(self, folder: Path, picks: Sequence[Sequence[int]]):
        """InputError when the folder lacks images or poses of a named view."""
        self.folder, self.picks = Path(folder), [tuple(int(v) for v in pick) for pick in picks]
        self.images = numbered_files(self.folder / "images", ".png")
        self.poses = numbered_files(self.folder / "poses", ".npy")
        for pick in self.picks:
            missing = [v for v in pick if v not in self.images or v not in self.poses]
            if missing:
                raise InputError(f"{self.folder}: no images/<vid>.png and poses/<vid>.npy for views {missing}")
        self.name = str(self.folder.resolve())
        self.dataset = self.folder.resolve().parent.name

    def true_c2w(self, view_id: int) -> np.ndarray:
        """The view's camera-to-world (4, 4), OpenGL axes, object frame: as the layout stores it."""
        c2w = np.load(self.poses[view_id])
        if c2w.shape != (4, 4):
            raise InputError(f"{self.poses[view_id]}: expected a 4x4 camera-to-world matrix, got {c2w.shape}")
        return c2w.astype(np.float64)

    def plan(self, protocol: EvaluationProtocol) -> list[EstimateTask]:
        """Each fixed sample on its first n views for every requested n it holds; the picks do not use the seed,
        the random baselines do."""
        cameras = [np.stack([self.true_c2w(v) for v in pick]) for pick in self.picks]
        tasks = tasks_for_picks(self.picks, cameras, sorted(set(protocol.view_counts)), protocol.seed)
        if not tasks:
            raise InputError(f"{self.folder}: its samples have {sorted({len(p) for p in self.picks})} views, "
                             f"fewer than any requested view count {sorted(protocol.view_counts)}")
        return tasks

    def views(self, view_ids: set[int]) -> tuple[dict[int, ViewInput], dict[int, str]]:
        return {v: read_png_view(self.images[v]) for v in view_ids}, {}

    def published(self, task: EstimateTask) -> dict[str, tuple[list[dict[str, Any]], dict[str, Any]]]:
        return {}

    def summary(self) -> dict[str, Any]:
        return {"views": len(self.images), "usable": len(set(self.images) & set(self.poses)), "skipped": 0}


def read_official_samples(path: Path) -> list[OfficialInput]:
    """The objects a samples JSON names (``data_root`` relative to the JSON's folder), in order of first mention."""
    try:
        spec = json.loads(Path(path).read_text())
        root = Path(path).parent / spec["data_root"]
        picks: dict[str, list[tuple[int, ...]]] = {}
        for sample in spec["samples"]:
            picks.setdefault(sample["name"], []).append((int(sample["anchor_vid"]),
                                                         *(int(v) for v in sample["target_vids"])))
    except (OSError, json.JSONDecodeError, KeyError, TypeError, ValueError) as err:
        raise InputError(f"{path}: not an ID-Pose samples file (data_root, samples: name, anchor_vid, "
                         f"target_vids): {type(err).__name__}: {err}") from None
    if not picks:
        raise InputError(f"{path}: names no samples")
    return [OfficialInput(root / name, object_picks) for name, object_picks in picks.items()]


def expand_paths(patterns: Sequence[str]) -> list[Path]:
    """The input arguments with globs expanded (sorted), duplicates dropped; InputError for a glob matching nothing."""
    paths: list[Path] = []
    for pattern in patterns:
        matches = sorted(glob.glob(pattern)) if glob.has_magic(pattern) else [pattern]
        if not matches:
            raise InputError(f"{pattern!r} matches no file")
        paths += [Path(match) for match in matches if Path(match) not in paths]
    return paths


def open_inputs(patterns: Sequence[str], ground_truth: GroundTruthOptions) -> list[DatasetInput]:
    """Every input the arguments name: a ``.json`` is an official samples file, a flight recorder's ``.mcap`` a
    recording, a folder without metadata.yaml that holds recordings each of them, anything else a bag.

    Raises ``InputError`` or ``BagError`` naming the first input that cannot be evaluated.
    """
    inputs: list[DatasetInput] = []
    for path in expand_paths(patterns):
        if path.suffix == ".json":
            inputs += read_official_samples(path)
            continue
        recordings = ([path] if is_recording(path) else recordings_in(path)
                      if path.is_dir() and not (path / "metadata.yaml").exists() else [])
        for source in recordings or [path]:
            try:
                inputs.append(RecordingInput(source, ground_truth) if recordings else BagInput(source, ground_truth))
            except BagError as err:
                raise BagError(f"{source}: {err}") from None
    names = [item.name for item in inputs]
    repeated = sorted({name for name in names if names.count(name) > 1})
    if repeated:
        raise InputError(f"inputs named more than once: {', '.join(repeated)}")
    return inputs
