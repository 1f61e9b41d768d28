"""The object catalogue: splits by object, the reserved random_urdfs never used, objects that render."""
from __future__ import annotations

import numpy as np
import pytest

from idpose_core.synthetic.catalogue import (
    BENCH_HELDOUT,
    CURVE_HELDOUT,
    HELDOUT_BLOBS,
    MESHES,
    RESERVED_BLOBS,
    TRAIN_BLOBS,
    blob,
    has_uv,
    heldout_objects,
    toy,
    training_objects,
)
from idpose_core.synthetic.scenes import SceneRenderer, random_camera_spheres


def blob_indices(objects) -> set[int]:
    return {int(spec.name.split("_")[1]) for spec in objects if spec.name.startswith("blob_")}


def test_the_splits_share_no_object_and_never_touch_the_reserved_blobs():
    train = training_objects(toys=20, mesh_variants=1)
    heldout = heldout_objects(0, len(HELDOUT_BLOBS))
    assert blob_indices(train) == set(TRAIN_BLOBS) and blob_indices(heldout) == set(HELDOUT_BLOBS)
    meshes = {part.mesh for spec in train + heldout for part in spec.parts}
    assert not any(mesh.startswith(f"random_urdfs/{index:03d}/") for mesh in meshes for index in RESERVED_BLOBS)
    train_names, heldout_names = {spec.name for spec in train}, {spec.name for spec in heldout}
    assert len(train_names) == len(train) and len(heldout_names) == len(heldout)
    assert not train_names & heldout_names
    held_toys = [spec for spec in heldout if spec.name.startswith("toy_")]
    train_toys = [spec for spec in train if spec.name.startswith("toy_")]
    assert {spec.parts for spec in held_toys}.isdisjoint({spec.parts for spec in train_toys})


def test_the_curve_and_the_benchmarks_use_disjoint_held_out_objects():
    curve, bench = heldout_objects(*CURVE_HELDOUT), heldout_objects(*BENCH_HELDOUT)
    assert len(bench) == 2 * BENCH_HELDOUT[1] and not {s.name for s in curve} & {s.name for s in bench}


def test_an_object_does_not_change_when_others_are_added():
    assert training_objects(toys=3, mesh_variants=0, blobs=2)[2] == training_objects(10, 2, 700)[700]
    assert heldout_objects(5, 1)[0] == blob(805) and heldout_objects(5, 1)[1] == toy("heldout", 5)
    assert blob(3, seed=1) != blob(3, seed=0)


def test_the_catalogue_is_varied():
    objects = training_objects(toys=5, mesh_variants=0, blobs=5)
    colours = {part.rgba for spec in objects for part in spec.parts if part.texture is None}
    assert len(colours) >= 8
    assert len(training_objects(toys=0, mesh_variants=2, blobs=0)) == 2 * len(MESHES)


def test_textures_go_only_on_meshes_with_uv_coordinates():
    objects = training_objects(toys=40, mesh_variants=3, blobs=0)
    textured = [part for spec in objects for part in spec.parts if part.texture is not None]
    assert textured and all(has_uv(part.mesh) for part in textured)


def test_bad_requests_name_the_problem():
    with pytest.raises(ValueError, match="split must be one of"):
        toy("test", 1)
    with pytest.raises(ValueError, match="out of range"):
        heldout_objects(90, 20)
    with pytest.raises(ValueError, match="blobs must be in"):
        training_objects(0, 0, blobs=801)


def test_every_family_renders_a_whole_object():
    objects = training_objects(toys=1, mesh_variants=1, blobs=1)
    families = [objects[0], objects[1], objects[-1]]  # a blob, a toy, a mesh
    rng = np.random.default_rng(0)
    for spec in families:
        with SceneRenderer(spec, 64) as renderer:
            for camera in random_camera_spheres(rng, 2):
                rgb, mask = renderer.render(*camera)
                assert 0.02 < mask.mean() < 0.6, spec.name
                assert not mask[0].any() and not mask[-1].any(), spec.name  # inside the frame
