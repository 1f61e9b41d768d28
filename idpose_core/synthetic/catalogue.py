"""The object catalogue a generalising model is trained and benchmarked on, split by object.

Three families, each procedurally varied in shape, colour and texture:

- ``blob_NNN``: a ``random_urdfs`` mesh in a random orientation and colour, with zero to two marker parts;
- ``toy_*``: two to four primitives (boxes, spheres, cones, tori, slabs) joined, each its own colour or texture;
- ``mesh_*``: another ``pybullet_data`` mesh (bunny, duck, mug, ...) recoloured or retextured.

``training_objects`` holds blobs ``TRAIN_BLOBS``, toys of the training stream and the meshes (the embedded model
trains on them and on the six demo objects); ``heldout_objects`` holds blobs ``HELDOUT_BLOBS`` and toys of another
stream, which no training run sees. ``random_urdfs`` ``RESERVED_BLOBS`` (900-999) are in neither: they are kept
for checks from outside the project, so nothing here trains, tunes or selects on them.
"""
from __future__ import annotations

import colorsys
from functools import cache

import numpy as np

from idpose_core.synthetic.scenes import DATA_PATH, ObjectSpec, Part, _part_vertices

TRAIN_BLOBS = range(0, 800)
HELDOUT_BLOBS = range(800, 900)
RESERVED_BLOBS = range(900, 1000)
SPLITS = ("train", "heldout")
_BLOB_STREAM, _MESH_STREAM, _TOY_STREAM = 0, 1, {"train": 2, "heldout": 3}
"""Each object draws from its own seeded stream, so an object does not change when others are added."""
CURVE_HELDOUT = (0, 24)
"""(start, count) of the held-out objects the training curve follows (and the probe timestep is chosen on)."""
BENCH_HELDOUT = (50, 24)
"""(start, count) of the held-out objects the benchmarks measure: never seen by training, nor by its curve."""
DEMO_HELDOUT = (80, 1)
"""(start, count) of the held-out objects in the shipped demo bags (``data/demo_bags/novel``)."""

PRIMITIVES = ("cube.obj", "sphere_smooth.obj", "racecar/meshes/cone.obj", "torus/torus_textured.obj",
              "domino/domino.obj", "jenga/jenga.obj")
MESHES = ("bunny.obj", "duck.obj", "teddy2_VHACD_CHs.obj", "objects/mug.obj", "lego/lego.obj", "soccerball.obj",
          "torus/torus_textured.obj", "racecar/meshes/cone.obj", "tray/tray_textured.obj", "quadruped/tmotor3.obj",
          "racecar/meshes/left_rear_wheel.obj", "franka_panda/meshes/collision/link4.obj",
          "franka_panda/meshes/collision/hand.obj", "xarm/xarm_description/meshes/xarm6/collision/link3_vhacd.obj",
          "laikago/chassis.obj")
TEXTURES = ("checker_grid.jpg", "checker_blue.png", "tex256.png", "cube.png", "colors16.png", "duckCM.png",
            "table/table.png", "jenga/jenga.png", "domino/domino.jpg", "quadruped/t-motor.jpg", "uvmap.png",
            "tray/tray.jpg", "racecar/meshes/wheel.jpg")
TEXTURE_ODDS = 0.35
"""Share of parts with UV coordinates that get a texture instead of a flat colour."""


def random_colour(rng: np.random.Generator) -> tuple[float, float, float, float]:
    """An opaque RGBA colour: any hue, mostly saturated, never near the white background."""
    hue, saturation, value = rng.uniform(), rng.uniform(0.25, 1.0), rng.uniform(0.2, 0.9)
    return (*colorsys.hsv_to_rgb(hue, saturation, value), 1.0)


@cache
def has_uv(mesh: str) -> bool:
    """True when the OBJ mesh carries texture coordinates (a texture can show on it)."""
    return any(line.startswith("vt ") for line in (DATA_PATH / mesh).read_text().splitlines())


def extent(vertices: np.ndarray) -> float:
    """The largest side of the bounding box of vertices (V, 3)."""
    return float(np.max(vertices.max(axis=0) - vertices.min(axis=0)))


@cache
def mesh_extent(mesh: str) -> float:
    """The mesh's ``extent`` in its own units (primitives are scaled to 1 by it)."""
    return extent(_part_vertices(Part(mesh)))


def _surface(mesh: str, rng: np.random.Generator) -> dict:
    """A part's look: a flat random colour, or (on meshes with UVs, with odds TEXTURE_ODDS) a random texture."""
    if has_uv(mesh) and rng.random() < TEXTURE_ODDS:
        return {"texture": str(rng.choice(TEXTURES))}
    return {"rgba": random_colour(rng)}


def _orientation(rng: np.random.Generator) -> tuple[float, float, float]:
    return tuple(float(a) for a in rng.uniform(-180.0, 180.0, size=3))


def _markers(vertices: np.ndarray, rng: np.random.Generator, count: int) -> tuple[Part, ...]:
    """``count`` small cubes or spheres in random colours on random vertices: colour cues that break symmetry."""
    size_of_object = extent(vertices)
    markers = []
    for _ in range(count):
        mesh = str(rng.choice(("cube.obj", "sphere_smooth.obj")))
        size = rng.uniform(0.15, 0.35) * size_of_object * (1.0 if mesh == "cube.obj" else 0.5)
        at = vertices[int(rng.integers(len(vertices)))]
        markers.append(Part(mesh, rgba=random_colour(rng), scale=(size,) * 3, position=tuple(float(x) for x in at),
                            orientation_deg=_orientation(rng)))
    return tuple(markers)


def blob(index: int, seed: int = 0) -> ObjectSpec:
    """``random_urdfs`` blob ``index``, randomly turned and coloured, with 0-2 markers (a third have none)."""
    rng = np.random.default_rng([seed, _BLOB_STREAM, index])
    mesh = f"random_urdfs/{index:03d}/{index:03d}.obj"
    body = Part(mesh, rgba=random_colour(rng), orientation_deg=_orientation(rng))
    markers = _markers(_part_vertices(body), rng, int(rng.choice(3, p=(1 / 3, 0.4, 1 - 1 / 3 - 0.4))))
    return ObjectSpec(f"blob_{index:03d}", (body, *markers))


def toy(split: str, index: int, seed: int = 0) -> ObjectSpec:
    """Toy ``index`` of ``split``'s own stream: two to four primitives joined, each scaled per axis, turned, placed
    near the others, with its own surface."""
    rng = np.random.default_rng([seed, _TOY_STREAM[_check_split(split)], index])
    parts, anchor = [], np.zeros(3)
    for _ in range(int(rng.integers(2, 5))):
        mesh = str(rng.choice(PRIMITIVES))
        scale = tuple(float(s) / mesh_extent(mesh) for s in rng.uniform(0.25, 1.0, size=3))
        position = anchor + rng.uniform(-0.3, 0.3, size=3)
        parts.append(Part(mesh, scale=scale, position=tuple(float(x) for x in position),
                          orientation_deg=_orientation(rng), **_surface(mesh, rng)))
        anchor = position if rng.random() < 0.5 else anchor
    prefix = "toy" if split == "train" else "toy_heldout"
    return ObjectSpec(f"{prefix}_{index:04d}", tuple(parts))


def mesh_object(mesh: str, variant: int, seed: int = 0) -> ObjectSpec:
    """Variant ``variant`` of a ``pybullet_data`` mesh: recoloured or retextured, turned at random, 0-1 marker."""
    rng = np.random.default_rng([seed, _MESH_STREAM, MESHES.index(mesh), variant])
    body = Part(mesh, orientation_deg=_orientation(rng), **_surface(mesh, rng))
    markers = _markers(_part_vertices(body), rng, int(rng.random() < 0.5))
    return ObjectSpec(f"mesh_{mesh.rsplit('/', 1)[-1][:-4]}_{variant}", (body, *markers))


def _check_split(split: str) -> str:
    if split not in SPLITS:
        raise ValueError(f"split must be one of {SPLITS}, got {split!r}")
    return split


def training_objects(toys: int, mesh_variants: int, blobs: int = len(TRAIN_BLOBS), seed: int = 0
                     ) -> list[ObjectSpec]:
    """The training catalogue: the first ``blobs`` of TRAIN_BLOBS, ``toys`` toys and ``mesh_variants`` variants of
    every mesh in MESHES (``seed`` varies every colour, orientation and toy)."""
    if not 0 <= blobs <= len(TRAIN_BLOBS):
        raise ValueError(f"blobs must be in [0, {len(TRAIN_BLOBS)}], got {blobs}")
    return ([blob(index, seed) for index in TRAIN_BLOBS[:blobs]] + [toy("train", k, seed) for k in range(toys)]
            + [mesh_object(mesh, variant, seed) for variant in range(mesh_variants) for mesh in MESHES])


def heldout_objects(start: int, count: int, seed: int = 0) -> list[ObjectSpec]:
    """Held-out objects no training run sees: HELDOUT_BLOBS[start:start + count] and held-out toys start.. (as
    many). Disjoint ranges serve disjoint purposes: CURVE_HELDOUT for the training curve, BENCH_HELDOUT for the
    benchmarks."""
    if start < 0 or count < 0 or start + count > len(HELDOUT_BLOBS):
        raise ValueError(f"held-out objects {start}..{start + count - 1} are out of range: there are "
                         f"{len(HELDOUT_BLOBS)} held-out blobs")
    return ([blob(index, seed) for index in HELDOUT_BLOBS[start:start + count]]
            + [toy("heldout", k, seed) for k in range(start, start + count)])
