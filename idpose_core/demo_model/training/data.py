"""The renders a training run uses, cached in its work dir, and the fixed held-out pairs it is checked on."""
from __future__ import annotations

import numpy as np

from idpose_core.demo_model.model import DemoDiffusionModel
from idpose_core.demo_model.training.options import TrainingOptions
from idpose_core.demo_model.training_data import (
    PairBatch,
    PairSource,
    RenderedViews,
    RobotCrops,
    cached_lit,
    cached_views,
    make_pairs,
    random_pairs,
)
from idpose_core.synthetic.catalogue import CURVE_HELDOUT, heldout_objects, training_objects
from idpose_core.synthetic.scenes import demo_objects


class TrainingData:
    """Every render the run uses: the demo objects' training and held-out cameras, the training catalogue, the
    held-out catalogue, each with its robot-crop renders under lamps."""

    def __init__(self, options: TrainingOptions):
        work, seed = options.work_dir, options.seed
        demo = demo_objects()
        self.demo = cached_views(work / f"train_{seed}.npz", demo, options.train_views, options.image_size, seed)
        self.demo_heldout = cached_views(work / f"heldout_{seed}.npz", demo, options.heldout_views,
                                         options.image_size, seed + 1000)
        self.demo_lit = cached_lit(work / f"lamps_{seed}_{options.lamps}.npz", demo, self.demo, seed + 2000,
                                   options.lamps)
        objects = training_objects(options.toys, options.mesh_variants, options.blobs, seed)
        self.catalogue = cached_views(work / f"catalogue_{seed}.npz", objects, options.catalogue_views,
                                      options.catalogue_size, seed + 4000)
        self.catalogue_lit = cached_lit(work / f"catalogue_lamps_{seed}.npz", objects, self.catalogue, seed + 5000, 1)
        held = heldout_objects(CURVE_HELDOUT[0], options.heldout_objects, seed)
        self.novel = cached_views(work / f"novel_{seed}.npz", held, 8, options.catalogue_size, seed + 6000)
        self.novel_lit = cached_lit(work / f"novel_lamps_{seed}.npz", held, self.novel, seed + 7000, 1)

    def sources(self, demo_share: float) -> list[PairSource]:
        """The pair pool's sources: the demo objects (``demo_share`` of the pairs) and the catalogue."""
        return [PairSource(self.demo, RobotCrops(self.demo_lit), demo_share),
                PairSource(self.catalogue, RobotCrops(self.catalogue_lit), 1.0 - demo_share)]

    def names(self) -> dict[str, list[str]]:
        """The objects of each part of the data, as training.json records them."""
        return {"demo": list(self.demo.names), "catalogue": list(self.catalogue.names),
                "heldout": list(self.novel.names)}


def fixed_pairs(views: RenderedViews, count: int, seed: int, model: DemoDiffusionModel,
                crops: RobotCrops | None = None) -> PairBatch:
    """A fixed set of held-out pairs (window scale 1.5, as at inference), as robot crops when ``crops`` are given."""
    rng = np.random.default_rng(seed)
    return make_pairs(views, *random_pairs(views, rng, count), model.downsample, crops=crops, rng=rng)
