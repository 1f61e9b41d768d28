"""The COLMAP baseline (pycolmap): SIFT extraction, exhaustive matching and incremental mapping on the n views
of one estimate, with the intrinsics fixed to the given camera matrix, in a temporary folder.

When the mapper cannot register every view, it runs again with fewer: on the views of its largest model
that holds the anchor, or without the view that has the fewest verified matches, until every view it is
given registers or only the anchor is left. That gives the paper's convergence counts: all views, fewer
views, or none.
"""
from __future__ import annotations

import contextlib
import tempfile
import time
from collections.abc import Iterator, Sequence
from pathlib import Path

import cv2
import numpy as np
import pycolmap

from idpose_core.baselines.result import BaselineEstimate, in_anchor_frame, scale_to_object_distance, status_of

MIN_INLIERS = pycolmap.TwoViewGeometryOptions().min_num_inliers  # 15
_QUIET = 3  # glog's FATAL: nothing below it reaches the terminal or a log file


@contextlib.contextmanager
def quiet_colmap() -> Iterator[None]:
    """Silence COLMAP's log while inside (it logs every step, and an error for every failed model)."""
    level = pycolmap.logging.minloglevel
    pycolmap.logging.minloglevel = _QUIET
    try:
        yield
    finally:
        pycolmap.logging.minloglevel = level


def _image_name(index: int) -> str:
    return f"{index:02d}.png"


def _pipeline_options(names: Sequence[str], seed: int) -> pycolmap.IncrementalPipelineOptions:
    """COLMAP's incremental mapper as shipped, except: intrinsics fixed, models of any size kept, the initial pair
    and each added view needing only the inliers that two-view verification asks (15, not 100 and 30: a few
    views of an object have no more), seeded, one thread."""
    options = pycolmap.IncrementalPipelineOptions()
    options.image_names = list(names)
    options.min_model_size = 2
    options.mapper.init_min_num_inliers = options.mapper.abs_pose_min_num_inliers = MIN_INLIERS
    options.ba_refine_focal_length = options.ba_refine_principal_point = options.ba_refine_extra_params = False
    options.random_seed, options.num_threads = seed, 1
    return options


def _verified_matches(database: Path, count: int) -> np.ndarray:
    """Verified inlier matches (count,) of each image with all the others, by image index."""
    totals = np.zeros(count, dtype=np.int64)
    with contextlib.closing(pycolmap.Database.open(database)) as db:
        index_of = {image.image_id: int(Path(image.name).stem) for image in db.read_all_images()}
        pair_ids, geometries = db.read_two_view_geometries()
        for pair_id, geometry in zip(pair_ids, geometries):
            for image_id in pycolmap.pair_id_to_image_pair(pair_id):
                totals[index_of[image_id]] += len(geometry.inlier_matches)
    return totals


def _registered_poses(reconstructions: dict[int, pycolmap.Reconstruction], count: int
                      ) -> tuple[np.ndarray, np.ndarray] | None:
    """(world-to-camera (count, 4, 4), registered (count,)) from the model with the anchor and the most views."""
    best = None
    for reconstruction in reconstructions.values():
        images = {int(Path(image.name).stem): image for image in reconstruction.images.values() if image.has_pose}
        if 0 in images and (best is None or len(images) > len(best)):
            best = images
    if best is None:
        return None
    cam_from_world = np.repeat(np.eye(4)[None], count, axis=0)
    for index, image in best.items():
        cam_from_world[index, :3] = image.cam_from_world().matrix()
    return cam_from_world, np.isin(np.arange(count), list(best))


def _map_with_fewer_views(database: Path, image_dir: Path, names: list[str], seed: int
                          ) -> tuple[np.ndarray, np.ndarray] | None:
    """Incremental mapping on every view, then on fewer until every view it is given registers:
    (world-to-camera (n, 4, 4), registered (n,)), or None when not even the anchor and one view do."""
    matches = _verified_matches(database, len(names))
    views = list(range(len(names)))
    while len(views) >= 2:
        found = _registered_poses(pycolmap.incremental_mapping(
            database, image_dir, image_dir.parent / f"sparse_{len(views)}",
            _pipeline_options([names[v] for v in views], seed)), len(names))
        kept = [] if found is None else [v for v in views if found[1][v]]
        if len(kept) == len(views):
            return found
        views = kept if len(kept) >= 2 else [v for v in views if v != min(views[1:], key=lambda v: matches[v])]
    return None


def estimate_colmap(images: Sequence[np.ndarray], camera_matrix: np.ndarray, object_distance: float, seed: int = 0
                    ) -> BaselineEstimate:
    """COLMAP on the views (RGB uint8, anchor first); poses scaled by the anchor's ``object_distance``."""
    start = time.perf_counter()
    fx, fy, cx, cy = camera_matrix[0, 0], camera_matrix[1, 1], camera_matrix[0, 2], camera_matrix[1, 2]
    reader = pycolmap.ImageReaderOptions()
    reader.camera_model, reader.camera_params = "PINHOLE", f"{fx},{fy},{cx},{cy}"
    extraction, matching = pycolmap.FeatureExtractionOptions(), pycolmap.FeatureMatchingOptions()
    extraction.num_threads = matching.num_threads = 1
    with tempfile.TemporaryDirectory(prefix="idpose_colmap_") as folder, quiet_colmap():
        image_dir, names = Path(folder) / "images", [_image_name(index) for index in range(len(images))]
        image_dir.mkdir()
        for name, image in zip(names, images):
            cv2.imwrite(str(image_dir / name), cv2.cvtColor(image, cv2.COLOR_RGB2BGR))
        database = Path(folder) / "database.db"
        pycolmap.set_random_seed(seed)
        pycolmap.extract_features(database, image_dir, names, camera_mode=pycolmap.CameraMode.SINGLE,
                                  reader_options=reader, extraction_options=extraction, device=pycolmap.Device.cpu)
        pycolmap.match_exhaustive(database, matching_options=matching, device=pycolmap.Device.cpu)
        found = _map_with_fewer_views(database, image_dir, names, seed)
    scaled = None if found is None else scale_to_object_distance(in_anchor_frame(found[0]), found[1], object_distance)
    if scaled is None:
        return BaselineEstimate.failure(len(images), time.perf_counter() - start)
    return BaselineEstimate(scaled, found[1], status_of(found[1]), time.perf_counter() - start)
