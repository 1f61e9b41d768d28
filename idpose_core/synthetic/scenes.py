"""Synthetic object scenes rendered with pybullet's TinyRenderer: objects, cameras and renders.

Every object is built from ``pybullet_data`` meshes, centred on the origin and scaled so that its
bounding box fits inside a sphere of ``OBJECT_RADIUS``; a camera at ``CAMERA_RADIUS`` with a 60 deg
field of view (the paper's ABO protocol) then always sees the whole object. Cameras sit at absolute
spherical coordinates ``(polar, azimuth, radius)`` around the origin (world up +z, polar 0 above
the object), look at the origin with no roll, and render on a white background with the object
mask taken from pybullet's segmentation buffer. Light is fixed in the world (``TRAINING_LIGHT`` unless a
``Light`` is given), so a render is a function of the camera pose and that light.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import Self

import numpy as np
import pybullet
import pybullet_data

from idpose_core.cameras import opengl_to_optical, spherical_to_c2w
from idpose_core.gravity import rz
from idpose_core.spherical import spherical_to_cartesian

CAMERA_RADIUS = 2.0
OBJECT_RADIUS = 0.9
FOV_DEG = 60.0
CAMERA_POLAR_DEG = (30.0, 150.0)  # the polar range random cameras are drawn from (0 = straight above)
DATA_PATH = Path(pybullet_data.getDataPath())


@dataclass(frozen=True)
class Light:
    """TinyRenderer's light: direction (towards the light, world frame), ambient, diffuse and specular shares,
    cast shadows or not."""

    direction: tuple[float, float, float]
    ambient: float
    diffuse: float
    shadow: bool
    specular: float = 0.05


TRAINING_LIGHT = Light((0.5, -0.7, 1.0), ambient=0.6, diffuse=0.5, shadow=False, specular=0.0)
"""The light of the white-background scenes: the demo model's clean training views and the plain bags."""


def random_light(rng: np.random.Generator, elevation_deg: tuple[float, float] = (35.0, 75.0),
                 ambient: tuple[float, float] = (0.5, 0.7), diffuse: tuple[float, float] = (0.4, 0.6)) -> Light:
    """A light from a random direction ``elevation_deg`` above the horizon, with shadows (a room's lamp)."""
    elevation, direction = np.radians(rng.uniform(*elevation_deg)), rng.uniform(0.0, 2.0 * math.pi)
    return Light((float(np.cos(elevation) * np.cos(direction)), float(np.cos(elevation) * np.sin(direction)),
                  float(np.sin(elevation))), float(rng.uniform(*ambient)), float(rng.uniform(*diffuse)), True)


@dataclass(frozen=True)
class Part:
    """One mesh of an object, placed in the object's own (unnormalised) frame.

    ``mesh`` and ``texture`` are paths relative to ``pybullet_data``; a texture only shows on meshes
    with UV coordinates (duck, soccer ball, table boxes), others keep the flat ``rgba`` colour.
    """

    mesh: str
    rgba: tuple[float, float, float, float] = (1.0, 1.0, 1.0, 1.0)
    scale: tuple[float, float, float] = (1.0, 1.0, 1.0)
    position: tuple[float, float, float] = (0.0, 0.0, 0.0)
    orientation_deg: tuple[float, float, float] = (0.0, 0.0, 0.0)
    texture: str | None = None


@dataclass(frozen=True)
class ObjectSpec:
    """A synthetic object: named parts, and its rotational symmetry about the vertical axis.

    ``symmetry_order`` k means the object looks the same after turning it by 360/k deg about +z
    (1 = no symmetry; a plain table is 2), so relative azimuths are only defined modulo 360/k.
    """

    name: str
    parts: tuple[Part, ...]
    symmetry_order: int = 1

    @property
    def symmetric(self) -> bool:
        """True when some azimuth turn other than a full one leaves the object's look unchanged."""
        return self.symmetry_order > 1


def _quaternion(orientation_deg: tuple[float, float, float]) -> tuple[float, ...]:
    return pybullet.getQuaternionFromEuler([math.radians(a) for a in orientation_deg])


@cache
def _mesh_vertices(mesh: str) -> np.ndarray:
    """Vertex positions (V, 3) of an OBJ mesh in ``pybullet_data``, read once."""
    rows = [line.split()[1:4] for line in (DATA_PATH / mesh).read_text().splitlines()
            if line.startswith("v ")]
    if not rows:
        raise ValueError(f"mesh {mesh!r} has no vertices")
    return np.asarray(rows, dtype=np.float64)


def _part_vertices(part: Part) -> np.ndarray:
    """The part's vertices (V, 3) in the object's frame."""
    rotation = np.asarray(pybullet.getMatrixFromQuaternion(_quaternion(part.orientation_deg)))
    scaled = _mesh_vertices(part.mesh) * np.asarray(part.scale)
    return scaled @ rotation.reshape(3, 3).T + np.asarray(part.position)


def normalisation(spec: ObjectSpec) -> tuple[np.ndarray, float]:
    """Centre (3,) and scale that move the object's bounding box into a sphere of ``OBJECT_RADIUS``."""
    vertices = np.concatenate([_part_vertices(part) for part in spec.parts])
    low, high = vertices.min(axis=0), vertices.max(axis=0)
    half_diagonal = 0.5 * float(np.linalg.norm(high - low))
    return 0.5 * (low + high), OBJECT_RADIUS / half_diagonal


def camera_up(polar: float, azimuth: float) -> np.ndarray:
    """Image-up direction (3,) of a camera at (polar, azimuth) looking at the origin, roll-free.

    It is +z projected onto the image plane, i.e. minus the polar tangent of the sphere; its limit
    stays defined straight above or below the object, where +z itself is the viewing direction.
    """
    return np.array([-math.cos(polar) * math.cos(azimuth),
                     -math.cos(polar) * math.sin(azimuth),
                     math.sin(polar)])


def add_object(client: int, spec: ObjectSpec, centre: tuple[float, float, float] = (0.0, 0.0, 0.0),
               radius: float = OBJECT_RADIUS, yaw_deg: float = 0.0) -> int:
    """Create the object's parts as one fixed multibody in pybullet ``client``: its bounding box centred on
    ``centre``, scaled into a sphere of ``radius``, turned by ``yaw_deg`` about +z. Returns the body id."""
    box_centre, factor = normalisation(spec)
    factor *= radius / OBJECT_RADIUS
    shapes, positions, orientations = [], [], []
    for part in spec.parts:
        shapes.append(pybullet.createVisualShape(
            pybullet.GEOM_MESH,
            fileName=str(DATA_PATH / part.mesh),
            meshScale=[s * factor for s in part.scale],
            rgbaColor=list(part.rgba),
            physicsClientId=client,
        ))
        positions.append(list((np.asarray(part.position) - box_centre) * factor))
        orientations.append(_quaternion(part.orientation_deg))
    count = len(shapes)  # every part is a fixed link of an invisible base at the centre
    body = pybullet.createMultiBody(
        baseMass=0,
        basePosition=list(centre),
        baseOrientation=_quaternion((0.0, 0.0, yaw_deg)),
        linkMasses=[0] * count,
        linkCollisionShapeIndices=[-1] * count,
        linkVisualShapeIndices=shapes,
        linkPositions=positions,
        linkOrientations=orientations,
        linkInertialFramePositions=[[0, 0, 0]] * count,
        linkInertialFrameOrientations=[[0, 0, 0, 1]] * count,
        linkParentIndices=[0] * count,
        linkJointTypes=[pybullet.JOINT_FIXED] * count,
        linkJointAxis=[[0, 0, 1]] * count,
        physicsClientId=client,
    )
    for link, part in enumerate(spec.parts):
        if part.texture is not None:
            texture = pybullet.loadTexture(str(DATA_PATH / part.texture), physicsClientId=client)
            pybullet.changeVisualShape(body, link, textureUniqueId=texture, physicsClientId=client)
    return body


def rolled_optical_frames(spheres: np.ndarray, rolls: np.ndarray) -> np.ndarray:
    """Optical camera-to-world frames (N, 4, 4) of cameras at ``spheres`` (N, 3) = (polar, azimuth, radius)
    looking at the origin, each turned about its optical axis by ``rolls`` (N,) radians."""
    turns = np.tile(np.eye(4), (len(rolls), 1, 1))
    turns[:, :3, :3] = np.stack([rz(float(roll)) for roll in rolls])
    return opengl_to_optical(spherical_to_c2w(np.asarray(spheres, dtype=np.float64))) @ turns


class PybulletClient:
    """One pybullet DIRECT client for a renderer's lifetime: a context manager, or call ``close()``."""

    def __init__(self):
        self._client: int | None = pybullet.connect(pybullet.DIRECT)

    def close(self) -> None:
        """Disconnect the pybullet client (idempotent)."""
        if self._client is not None:
            pybullet.disconnect(physicsClientId=self._client)
            self._client = None

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class SceneRenderer(PybulletClient):
    """Renders one object from spherical camera poses in its own pybullet DIRECT client.

    ``render(polar, azimuth, radius)`` (radians) -> ``(rgb uint8 (H, W, 3) on white, mask bool
    (H, W))``. Use as a context manager or call ``close()`` to release the client.
    """

    def __init__(self, spec: ObjectSpec, image_size: int = 256, fov_deg: float = FOV_DEG):
        if image_size < 8:
            raise ValueError(f"image_size must be at least 8 pixels, got {image_size}")
        if not 1.0 <= fov_deg < 180.0:
            raise ValueError(f"fov_deg must be in [1, 180), got {fov_deg}")
        self.spec = spec
        self.image_size = int(image_size)
        self.fov_deg = float(fov_deg)
        super().__init__()
        add_object(self._client, spec)

    def render(self, polar: float, azimuth: float, radius: float = CAMERA_RADIUS, roll: float = 0.0,
               light: Light = TRAINING_LIGHT) -> tuple[np.ndarray, np.ndarray]:
        """RGB uint8 (H, W, 3) with white background and foreground mask bool (H, W), under ``light``.

        ``roll`` (radians) turns the camera about its optical axis: its optical frame is the upright
        one's times ``rz(roll)`` (``idpose_core.gravity``), as ``rolled_optical_frames`` gives it.
        """
        if radius <= OBJECT_RADIUS:
            raise ValueError(f"radius {radius} puts the camera inside the object (radius {OBJECT_RADIUS})")
        eye = spherical_to_cartesian(np.array([polar, azimuth, radius], dtype=np.float64))
        up = camera_up(polar, azimuth) if roll == 0.0 else -rolled_optical_frames(
            np.array([[polar, azimuth, radius]]), np.array([roll]))[0, :3, 1]
        view = pybullet.computeViewMatrix(list(eye), [0.0, 0.0, 0.0], list(up))
        projection = pybullet.computeProjectionMatrixFOV(
            fov=self.fov_deg, aspect=1.0, nearVal=max(radius - 2 * OBJECT_RADIUS, 0.05),
            farVal=radius + 2 * OBJECT_RADIUS)
        size = self.image_size
        _, _, rgba, _, segmentation = pybullet.getCameraImage(
            size, size, viewMatrix=view, projectionMatrix=projection,
            renderer=pybullet.ER_TINY_RENDERER, lightDirection=list(light.direction),
            lightAmbientCoeff=light.ambient, lightDiffuseCoeff=light.diffuse, lightSpecularCoeff=light.specular,
            shadow=int(light.shadow),
            physicsClientId=self._client)
        rgb = np.asarray(rgba, dtype=np.uint8).reshape(size, size, 4)[..., :3].copy()
        mask = np.asarray(segmentation).reshape(size, size) >= 0
        rgb[~mask] = 255
        return rgb, mask


def random_camera_spheres(rng: np.random.Generator, n: int, polar_deg: tuple[float, float] = CAMERA_POLAR_DEG,
                          radius: float = CAMERA_RADIUS) -> np.ndarray:
    """``n`` cameras (n, 3) = (polar, azimuth, radius) radians, uniform on the sphere's polar band."""
    low, high = (math.radians(a) for a in polar_deg)
    if not 0.0 <= low <= high <= math.pi:
        raise ValueError(f"polar_deg must satisfy 0 <= low <= high <= 180, got {polar_deg}")
    cos_polar = rng.uniform(math.cos(high), math.cos(low), size=n)
    azimuth = rng.uniform(0.0, 2.0 * math.pi, size=n)
    return np.stack([np.arccos(cos_polar), azimuth, np.full(n, float(radius))], axis=-1)


# ----- object sets -------------------------------------------------------------------------------

_PALETTE = (
    (0.90, 0.20, 0.15, 1.0), (0.15, 0.45, 0.90, 1.0), (0.10, 0.70, 0.30, 1.0), (0.95, 0.75, 0.10, 1.0),
    (0.60, 0.25, 0.75, 1.0), (0.95, 0.45, 0.10, 1.0), (0.10, 0.75, 0.80, 1.0), (0.35, 0.35, 0.35, 1.0),
)


def _blob(index: int, rng: np.random.Generator) -> ObjectSpec:
    """A ``random_urdfs`` blob, randomly turned and coloured, with a differently coloured marker cube.

    The marker sits on a random vertex of the blob: it breaks any accidental symmetry of the blob
    and gives the views a colour cue.
    """
    mesh = f"random_urdfs/{index:03d}/{index:03d}.obj"
    orientation = tuple(float(a) for a in rng.uniform(-180, 180, size=3))
    vertices = _part_vertices(Part(mesh, orientation_deg=orientation))
    extent = float(np.max(vertices.max(axis=0) - vertices.min(axis=0)))
    marker_at = vertices[int(rng.integers(len(vertices)))]
    body, marker = rng.choice(len(_PALETTE), size=2, replace=False)
    return ObjectSpec(
        name=f"blob_{index:03d}",
        parts=(
            Part(mesh, rgba=_PALETTE[int(body)], orientation_deg=orientation),
            Part("cube.obj", rgba=_PALETTE[int(marker)], scale=(0.3 * extent,) * 3,
                 position=tuple(float(x) for x in marker_at)),
        ),
    )


def _table(name: str, rgba: tuple, legs_rgba: tuple) -> ObjectSpec:
    """A plain table (top and four legs), looking the same after a half turn: symmetry order 2."""
    legs = tuple(Part("cube.obj", rgba=legs_rgba, scale=(0.1, 0.1, 0.58), position=(x, y, 0.29))
                 for x in (-0.6, 0.6) for y in (-0.35, 0.35))
    return ObjectSpec(name, (Part("cube.obj", rgba=rgba, scale=(1.5, 0.9, 0.06), position=(0, 0, 0.6)),) + legs,
                      symmetry_order=2)


def demo_objects() -> list[ObjectSpec]:
    """The fixed demo set: 6 distinctively coloured/textured objects (also the small model's training set)."""
    return [
        ObjectSpec("duck", (Part("duck.obj", texture="duckCM.png", orientation_deg=(90, 0, 0)),)),
        ObjectSpec("teddy", (Part("teddy2_VHACD_CHs.obj", rgba=(0.60, 0.40, 0.20, 1.0), orientation_deg=(90, 0, 0)),)),
        ObjectSpec("mug", (Part("objects/mug.obj", rgba=(0.90, 0.20, 0.15, 1.0)),
                           Part("cube.obj", rgba=(0.95, 0.75, 0.10, 1.0), scale=(0.03, 0.03, 0.03),
                                position=(0.04, 0.0, 0.085)))),
        ObjectSpec("soccerball", (
            Part("soccerball.obj", texture="colors16.png"),
            Part("cube.obj", rgba=(0.10, 0.70, 0.30, 1.0), scale=(0.4, 0.4, 0.4), position=(0.45, 0.0, 0.3)),
        )),
        ObjectSpec("lego", (
            Part("lego/lego.obj", rgba=(0.95, 0.75, 0.10, 1.0), orientation_deg=(90, 0, 0)),
            Part("cube.obj", rgba=(0.60, 0.25, 0.75, 1.0), scale=(0.1, 0.1, 0.1), position=(0.32, 0.16, 0.23)),
        )),
        ObjectSpec("desk", (
            Part("cube.obj", texture="table/table.png", scale=(1.5, 0.9, 0.06), position=(0, 0, 0.6)),
            Part("cube.obj", rgba=(0.15, 0.45, 0.90, 1.0), scale=(0.1, 0.1, 0.58), position=(-0.6, -0.35, 0.29)),
            Part("cube.obj", rgba=(0.90, 0.20, 0.15, 1.0), scale=(0.1, 0.1, 0.58), position=(0.6, -0.35, 0.29)),
            Part("cube.obj", rgba=(0.10, 0.70, 0.30, 1.0), scale=(0.1, 0.1, 0.58), position=(-0.6, 0.35, 0.29)),
            Part("cube.obj", rgba=(0.95, 0.75, 0.10, 1.0), scale=(0.5, 0.3, 0.3), position=(0.35, 0.2, 0.78)),
        )),
    ]


def oracle_objects(count: int = 12, seed: int = 0) -> list[ObjectSpec]:
    """Held-out asymmetric objects for solver tests and benchmarks: ``random_urdfs`` 000.. blobs."""
    rng = np.random.default_rng(seed)
    return [_blob(index, rng) for index in range(count)]


def symmetric_objects() -> list[ObjectSpec]:
    """Objects that look the same after a half turn (symmetry order 2): true pose ambiguity."""
    return [
        _table("table_grey", (0.55, 0.55, 0.55, 1.0), (0.35, 0.35, 0.35, 1.0)),
        _table("table_blue", (0.15, 0.45, 0.90, 1.0), (0.95, 0.75, 0.10, 1.0)),
        ObjectSpec("bar", (Part("cube.obj", rgba=(0.10, 0.70, 0.30, 1.0), scale=(1.2, 0.35, 0.5)),
                           Part("cube.obj", rgba=(0.90, 0.20, 0.15, 1.0), scale=(0.3, 0.5, 0.7))),
                   symmetry_order=2),
    ]


def textured_objects() -> list[ObjectSpec]:
    """Objects covered in detailed textures, without symmetry: material for feature matching (SIFT, COLMAP).

    A cube with a numbered label on every face, a duck wrapped in a labelled UV grid, and boxes printed
    with a motor picture carrying one of the others (which breaks the box's half-turn symmetry).
    """
    numbered = "jenga/jenga.obj", "jenga/jenga.png"
    motor = "quadruped/t-motor.jpg"
    return [
        ObjectSpec("numbered_cube", (Part(numbered[0], texture=numbered[1]),)),
        ObjectSpec("uv_duck", (Part("duck.obj", texture="uvmap.png", orientation_deg=(90, 0, 0)),)),
        ObjectSpec("motor_crate", (
            Part("cube.obj", texture=motor, scale=(1.0, 0.7, 0.5)),
            Part(numbered[0], texture=numbered[1], scale=(0.3, 0.3, 0.3), position=(0.3, 0.2, 0.4)),
        )),
        ObjectSpec("duck_on_crate", (
            Part("cube.obj", texture=motor, scale=(1.0, 0.8, 0.4)),
            Part("duck.obj", texture="uvmap.png", orientation_deg=(90, 0, 0), scale=(0.35, 0.35, 0.35),
                 position=(0.0, 0.0, 0.2)),
        )),
    ]
