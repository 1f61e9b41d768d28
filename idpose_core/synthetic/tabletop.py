"""A robot's view of an object: the target on a textured table among other objects, in a room, by an RGB-D camera.

Metric units. The world origin is the target's centre (its bounding-box centre, as for the white-
background scenes), world up +z; the table top lies under the target, the room's floor 0.75 m below
it and four textured walls around. Distractors stand on the table around the target, one of them
close behind it as seen from the first camera. ``challenge`` layouts stage what makes depth segmentation
hard: a target with a part standing out towards the camera, a box touching the target, a backdrop panel
10-30 cm behind it, the target standing on a box of its own size; ``off_centre_camera`` aims a camera beside the
target, no distractor nearer the centre.
A render gives the colour image (no alpha), the depth
along the optical axis in metres, and the target's true mask.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np
import pybullet

from idpose_core.synthetic.scenes import (
    DATA_PATH,
    OBJECT_RADIUS,
    TRAINING_LIGHT,
    Light,
    ObjectSpec,
    Part,
    PybulletClient,
    _part_vertices,
    add_object,
    normalisation,
    random_light,
)

TARGET_RADIUS = 0.1  # m: the target fits a ball of this radius (a 20 cm object)
TABLE_SIZE = (1.4, 1.0, 0.04)  # m
FLOOR_DROP = 0.75  # m from the table top to the floor
ROOM_HALF_SIDE = 1.8  # m
WALL_HEIGHT = 2.5  # m
TABLE_TEXTURES = ("table/table.png", "checker_grid.jpg", "tray/tray.jpg", "domino/domino.jpg")
WALL_TEXTURES = ("tex256.png", "uvmap.png", "checker_blue.png", "jenga/jenga.png", "cube.png")
DISTRACTOR_TEXTURES = ("jenga/jenga.png", "domino/domino.jpg", "checker_blue.png", "uvmap.png")
CHALLENGES = ("clutter", "parts", "touching", "backdrop", "off_centre", "near_backdrop", "on_box")
BACKDROP_GAP = (0.10, 0.30)  # m from the target's bounding ball to the backdrop panel
NEAR_BACKDROP_GAP = (0.0, 0.04)  # m, for "near_backdrop": a target a few centimetres in front of a wall
PEDESTAL_WIDTH = (1.0, 1.2)  # of the target's width and depth: for "on_box", the box under it (its own size)
PEDESTAL_HEIGHT = (0.6, 1.2)  # of the target's height
OFF_CENTRE = (0.3, 0.65)  # of the way from the image centre to its edge: where an off-centre target's centre sits
FAIR_MARGIN = 0.15  # of that way: how much farther out than the target every distractor's centre is
AIM_TRIES = 100
STEREO_SD_AT_1M = 0.004  # m: an active stereo camera's depth noise at 1 m (a D435 at 848 px: 2-4 mm)
STEREO_EDGE_JUMP = 0.03  # of the depth: a step between neighbours this large is an edge, with no reading around it
STEREO_EDGE_PX = 2  # px of holes either side of such an edge
LOOSE_BOX = (0.1, 0.3)  # of the box's side: how much a detector's box overshoots the object on each side
_COLOURS = ((0.85, 0.3, 0.2, 1.0), (0.2, 0.5, 0.85, 1.0), (0.3, 0.7, 0.3, 1.0), (0.9, 0.8, 0.2, 1.0),
            (0.6, 0.3, 0.7, 1.0), (0.2, 0.75, 0.8, 1.0))


@dataclass(frozen=True)
class Placement:
    """An object in the scene: bounding-box ``centre`` (m), fitted into a ball of ``radius``, turned ``yaw_deg``."""

    spec: ObjectSpec
    centre: tuple[float, float, float]
    radius: float
    yaw_deg: float = 0.0


@dataclass(frozen=True)
class TabletopLayout:
    """Everything a render depends on besides the camera."""

    target: Placement
    distractors: tuple[Placement, ...]
    table_top: float  # z of the table top (m), or of the floor without a table
    table_texture: str
    wall_textures: tuple[str, str, str, str]
    light: Light
    table: bool = True  # False: everything stands on the floor (an object too big for a table)


def half_extents(spec: ObjectSpec, radius: float) -> np.ndarray:
    """Half the sides (3,) (m) of the object's bounding box once fitted into a ball of ``radius``."""
    vertices = np.concatenate([_part_vertices(part) for part in spec.parts])
    _, factor = normalisation(spec)
    return 0.5 * np.ptp(vertices, axis=0) * factor * radius / OBJECT_RADIUS


def half_height(spec: ObjectSpec, radius: float) -> float:
    """Half the height (m) of the object's bounding box once fitted into a ball of ``radius``."""
    return float(half_extents(spec, radius)[2])


def _pedestal(rng: np.random.Generator, target: ObjectSpec, target_radius: float) -> Placement:
    """A textured box of the target's own size right under it (``PEDESTAL_WIDTH``, ``PEDESTAL_HEIGHT``): the target
    stands on its top, the box on the table."""
    half = half_extents(target, target_radius)
    sides = (*(2 * half[:2] * rng.uniform(*PEDESTAL_WIDTH, size=2)), 2 * half[2] * float(rng.uniform(*PEDESTAL_HEIGHT)))
    spec = ObjectSpec("pedestal", (Part("cube.obj", scale=tuple(float(v) for v in sides),
                                        texture=DISTRACTOR_TEXTURES[int(rng.integers(len(DISTRACTOR_TEXTURES)))]),))
    return Placement(spec, (0.0, 0.0, -half[2] - sides[2] / 2), 0.5 * float(np.linalg.norm(sides)))


def _distractor_pool(rng: np.random.Generator, count: int) -> list[ObjectSpec]:
    """Blobs (``random_urdfs`` 700..) in plain colours and textured boxes, none of them a demo object."""
    specs = []
    for k in range(count):
        if rng.random() < 0.5:
            index = 700 + int(rng.integers(0, 200))
            colour = _COLOURS[int(rng.integers(len(_COLOURS)))]
            specs.append(ObjectSpec(f"blob_{index}", (Part(f"random_urdfs/{index:03d}/{index:03d}.obj", rgba=colour),)))
        else:
            sides = tuple(float(v) for v in rng.uniform(0.4, 1.0, size=3))
            texture = DISTRACTOR_TEXTURES[int(rng.integers(len(DISTRACTOR_TEXTURES)))]
            specs.append(ObjectSpec(f"box_{k}", (Part("cube.obj", scale=sides, texture=texture),)))
    return specs


def parts_target(rng: np.random.Generator) -> ObjectSpec:
    """A body with a head standing out in front of it (towards +x) at another depth, as a duck's head in front of
    its body: a textured box and a smaller one of another colour on its front top edge."""
    body = tuple(float(v) for v in rng.uniform((0.5, 0.5, 0.4), (0.8, 0.7, 0.6)))
    head = float(rng.uniform(0.2, 0.3))
    reach = float(rng.uniform(0.15, 0.3))  # how far the head sticks out beyond the body's front
    texture = DISTRACTOR_TEXTURES[int(rng.integers(len(DISTRACTOR_TEXTURES)))]
    colour = _COLOURS[int(rng.integers(len(_COLOURS)))]
    return ObjectSpec("head_and_body", (
        Part("cube.obj", scale=body, texture=texture),
        Part("cube.obj", rgba=colour, scale=(head, head, head),
             position=(body[0] / 2 + reach - head / 2, 0.0, body[2] / 2 + head / 2 - 0.05))))


def _backdrop(rng: np.random.Generator, table_top: float, camera_azimuth: float, target_radius: float,
              gap: tuple[float, float] = BACKDROP_GAP) -> Placement:
    """A textured panel standing on the table ``gap`` (m, drawn in that range) behind the target's bounding ball as
    seen from ``camera_azimuth``, facing the camera (its broad side across the view)."""
    sides = (0.04, 1.0, float(rng.uniform(0.5, 0.8)))
    texture = WALL_TEXTURES[int(rng.integers(len(WALL_TEXTURES)))]
    spec = ObjectSpec("backdrop", (Part("cube.obj", scale=sides, texture=texture),))
    radius = float(rng.uniform(0.25, 0.35))
    distance = target_radius + float(rng.uniform(*gap)) + sides[0] / 2
    azimuth = camera_azimuth + math.pi + float(rng.uniform(-0.2, 0.2))
    return Placement(spec, (distance * math.cos(azimuth), distance * math.sin(azimuth),
                            table_top + half_height(spec, radius)), radius, math.degrees(azimuth))


def random_layout(target: ObjectSpec, rng: np.random.Generator, behind_azimuth: float,
                  challenge: str = "clutter", random_lighting: bool = True,
                  target_radius: float = TARGET_RADIUS, table: bool = True) -> TabletopLayout:
    """A seeded scene around ``target``: 2-4 distractors (one close behind the target as seen from azimuth
    ``behind_azimuth + pi``, the others 0.2-0.5 m away, none overlapping), random textures and light.

    ``challenge`` (``CHALLENGES``): "parts" turns the target's front (+x) towards ``behind_azimuth``;
    "touching" puts the first distractor, a box, against the target's side as seen from there; "backdrop"
    adds a panel 10-30 cm behind the target, "near_backdrop" 0-4 cm behind its bounding ball (a wall it almost
    touches); "on_box" stands the target on a box of its own size (the table that much lower, the box the first
    placement); "clutter" and "off_centre" (a matter of the camera) add nothing.
    ``random_lighting`` False lights the scene with ``TRAINING_LIGHT`` (the light is drawn either way, so the
    rest of the layout is the same). ``target_radius`` (m): the ball the target fits (distractors keep their sizes
    and stand around it); ``table`` False stands everything on the floor (a chair before a mobile robot).
    """
    if challenge not in CHALLENGES:
        raise ValueError(f"challenge must be one of {', '.join(CHALLENGES)}, got {challenge!r}")
    placed: list[Placement] = [_pedestal(rng, target, target_radius)] if challenge == "on_box" else []
    table_top = -half_height(target, target_radius) - sum(2 * half_height(p.spec, p.radius) for p in placed)
    count = int(rng.integers(2, 5))
    pool = _distractor_pool(rng, count)
    if challenge == "touching":
        sides = tuple(float(v) for v in rng.uniform(0.5, 1.0, size=3))
        pool[0] = ObjectSpec("box_touching", (Part("cube.obj", scale=sides, texture=DISTRACTOR_TEXTURES[
            int(rng.integers(len(DISTRACTOR_TEXTURES)))]),))
    reach = max([target_radius] + [float(np.hypot(*half_extents(p.spec, p.radius)[:2])) for p in placed])
    for k, spec in enumerate(pool):
        radius = float(rng.uniform(0.05, 0.1))
        for _ in range(100):
            if k == 0 and challenge == "touching":  # bounding balls overlapping: the box leans on the target
                side = 1.0 if rng.random() < 0.5 else -1.0
                distance = 0.8 * (target_radius + radius)
                azimuth = behind_azimuth + side * (math.pi / 2 + rng.uniform(-0.4, 0.4))
            elif k == 0:  # close behind what stands at the centre (the target, or the box under it)
                distance, azimuth = reach + radius + 0.02, behind_azimuth + math.pi + rng.uniform(-0.3, 0.3)
            else:
                distance, azimuth = target_radius + rng.uniform(0.1, 0.4), rng.uniform(0.0, 2.0 * math.pi)
            x, y = distance * math.cos(azimuth), distance * math.sin(azimuth)
            clear = all(math.hypot(x - p.centre[0], y - p.centre[1]) > radius + p.radius + 0.02 for p in placed)
            if clear:
                break
        z = table_top + half_height(spec, radius)
        placed.append(Placement(spec, (x, y, z), radius, float(rng.uniform(0.0, 360.0))))
    if challenge == "backdrop":
        placed.append(_backdrop(rng, table_top, behind_azimuth, target_radius))
    if challenge == "near_backdrop":
        placed.append(_backdrop(rng, table_top, behind_azimuth, target_radius, NEAR_BACKDROP_GAP))
    light = random_light(rng)
    if not random_lighting:
        light = TRAINING_LIGHT
    yaw = math.degrees(behind_azimuth) if challenge == "parts" else 0.0
    walls = tuple(WALL_TEXTURES[int(i)] for i in rng.integers(0, len(WALL_TEXTURES), size=4))
    return TabletopLayout(
        target=Placement(target, (0.0, 0.0, 0.0), target_radius, yaw),
        distractors=tuple(placed), table_top=table_top,
        table_texture=TABLE_TEXTURES[int(rng.integers(len(TABLE_TEXTURES)))], wall_textures=walls, light=light,
        table=table)


@dataclass(frozen=True)
class TabletopFrame:
    """One render: ``rgb`` (H, W, 3) uint8, ``depth`` (H, W) float32 metres along the optical axis,
    ``target_mask`` (H, W) bool (the target's visible pixels)."""

    rgb: np.ndarray
    depth: np.ndarray
    target_mask: np.ndarray


class TabletopRenderer(PybulletClient):
    """Renders a ``TabletopLayout`` from optical camera poses in its own pybullet DIRECT client (a context
    manager, or call ``close()``)."""

    def __init__(self, layout: TabletopLayout, image_size: int = 320, fov_deg: float = 60.0,
                 near: float = 0.05, far: float = 6.0):
        self.layout, self.image_size, self.fov_deg, self.near, self.far = layout, image_size, fov_deg, near, far
        super().__init__()
        self._target = add_object(self._client, layout.target.spec, layout.target.centre, layout.target.radius,
                                  layout.target.yaw_deg)
        for placement in layout.distractors:
            add_object(self._client, placement.spec, placement.centre, placement.radius, placement.yaw_deg)
        width, depth, thickness = TABLE_SIZE
        top = layout.table_top
        if layout.table:
            self._box((0.0, 0.0, top - thickness / 2), (width, depth, thickness), layout.table_texture)
            for x in (-0.6 * width / 1.4, 0.6 * width / 1.4):
                for y in (-0.4 * depth, 0.4 * depth):
                    self._box((x, y, top - FLOOR_DROP / 2), (0.05, 0.05, FLOOR_DROP - thickness), None,
                              (0.3, 0.25, 0.2, 1))
        floor = top - FLOOR_DROP if layout.table else top
        side = 2 * ROOM_HALF_SIDE
        self._box((0.0, 0.0, floor - 0.01), (side, side, 0.02), "checker_grid.jpg")
        for k, (x, y, sx, sy) in enumerate(((ROOM_HALF_SIDE, 0, 0.02, side), (-ROOM_HALF_SIDE, 0, 0.02, side),
                                            (0, ROOM_HALF_SIDE, side, 0.02), (0, -ROOM_HALF_SIDE, side, 0.02))):
            self._box((x, y, floor + WALL_HEIGHT / 2), (sx, sy, WALL_HEIGHT), layout.wall_textures[k])

    def _box(self, centre, sides, texture: str | None, rgba=(1.0, 1.0, 1.0, 1.0)) -> None:
        """A textured box (cube.obj spans 1 m per side; its UVs carry the texture)."""
        shape = pybullet.createVisualShape(pybullet.GEOM_MESH, fileName=str(DATA_PATH / "cube.obj"),
                                           meshScale=list(sides), rgbaColor=list(rgba), physicsClientId=self._client)
        body = pybullet.createMultiBody(baseMass=0, baseVisualShapeIndex=shape, basePosition=list(centre),
                                        physicsClientId=self._client)
        if texture is not None:
            texture_id = pybullet.loadTexture(str(DATA_PATH / texture), physicsClientId=self._client)
            pybullet.changeVisualShape(body, -1, textureUniqueId=texture_id, physicsClientId=self._client)

    def render(self, world_from_optical: np.ndarray) -> TabletopFrame:
        """The scene seen by an optical camera at ``world_from_optical`` (4, 4) (REP 103 axes)."""
        frame = np.asarray(world_from_optical, dtype=np.float64)
        eye, forward, image_up = frame[:3, 3], frame[:3, 2], -frame[:3, 1]
        view = pybullet.computeViewMatrix(list(eye), list(eye + forward), list(image_up))
        projection = pybullet.computeProjectionMatrixFOV(fov=self.fov_deg, aspect=1.0, nearVal=self.near,
                                                         farVal=self.far)
        size, light = self.image_size, self.layout.light
        _, _, rgba, depth_buffer, segmentation = pybullet.getCameraImage(
            size, size, viewMatrix=view, projectionMatrix=projection, renderer=pybullet.ER_TINY_RENDERER,
            lightDirection=list(light.direction), lightAmbientCoeff=light.ambient, lightDiffuseCoeff=light.diffuse,
            lightSpecularCoeff=light.specular, shadow=int(light.shadow), physicsClientId=self._client)
        rgb = np.asarray(rgba, dtype=np.uint8).reshape(size, size, 4)[..., :3].copy()
        buffer = np.asarray(depth_buffer, dtype=np.float64).reshape(size, size)
        depth = self.far * self.near / (self.far - (self.far - self.near) * buffer)
        mask = np.asarray(segmentation).reshape(size, size) == self._target
        return TabletopFrame(rgb, depth.astype(np.float32), mask)


def tabletop_cameras(rng: np.random.Generator, count: int, polar_deg: tuple[float, float] = (45.0, 75.0),
                     distance: tuple[float, float] = (0.45, 0.65)) -> np.ndarray:
    """``count`` cameras (count, 3) = (polar, azimuth, radius) above the table looking at the target."""
    low, high = (math.radians(a) for a in polar_deg)
    return np.stack([rng.uniform(low, high, count), rng.uniform(0.0, 2.0 * math.pi, count),
                     rng.uniform(*distance, count)], axis=-1)


def _look_at(eye: np.ndarray, aim: np.ndarray) -> np.ndarray:
    """Optical camera-to-world frame (4, 4) of a roll-free camera at ``eye`` looking at ``aim``."""
    forward = (aim - eye) / np.linalg.norm(aim - eye)
    right = np.cross(forward, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    frame = np.eye(4)
    frame[:3, 0], frame[:3, 1], frame[:3, 2], frame[:3, 3] = right, np.cross(forward, right), forward, eye
    return frame


def _eye(sphere: np.ndarray) -> np.ndarray:
    polar, azimuth, radius = (float(v) for v in sphere)
    return radius * np.array([math.sin(polar) * math.cos(azimuth), math.sin(polar) * math.sin(azimuth),
                              math.cos(polar)])


def challenge_camera(sphere: np.ndarray) -> np.ndarray:
    """Optical camera-to-world frame (4, 4) of a roll-free camera at ``sphere`` = (polar, azimuth, radius) looking
    at the target."""
    return _look_at(_eye(sphere), np.zeros(3))


def image_offset(frame: np.ndarray, point: np.ndarray, fov_deg: float) -> float:
    """How far ``point`` (3,) projects from the image centre of the camera ``frame`` (4, 4), as a share of the way
    to the edge of a square image of ``fov_deg`` (inf behind the camera)."""
    local = (np.asarray(point, dtype=np.float64) - frame[:3, 3]) @ frame[:3, :3]
    if local[2] <= 0:
        return math.inf
    return float(np.hypot(local[0], local[1]) / local[2] / math.tan(math.radians(fov_deg) / 2))


def off_centre_camera(sphere: np.ndarray, layout: TabletopLayout, rng: np.random.Generator,
                      fov_deg: float = 60.0, crowded: bool = False) -> np.ndarray | None:
    """A camera at ``sphere`` aimed beside the target, so that the target's centre sits about ``OFF_CENTRE`` of
    the way from the image centre to the edge, yet every distractor's centre at least ``FAIR_MARGIN`` farther
    out: aimed roughly at the target, the view is still about it (with a distractor nearer the centre the
    target would be the odd choice, as a distractor off-centre is in a centred view). ``crowded``: a distractor
    ``FAIR_MARGIN`` nearer the centre instead, a view only a region of interest makes about the target. The aim
    is drawn afresh until that holds; None when ``AIM_TRIES`` draws do not find one."""
    eye = _eye(sphere)
    forward = -eye / np.linalg.norm(eye)
    right = np.cross(forward, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    down = np.cross(forward, right)
    half = math.radians(fov_deg) / 2
    for _ in range(AIM_TRIES):
        angle = math.atan(rng.uniform(*OFF_CENTRE) * math.tan(half))
        direction = rng.uniform(0.0, 2.0 * math.pi)
        offset = np.linalg.norm(eye) * math.tan(angle) * (math.cos(direction) * right + math.sin(direction) * down)
        frame = _look_at(eye, -offset)  # aim beside the target: it appears displaced by ``offset``
        target = image_offset(frame, np.zeros(3), fov_deg)
        margin = min((image_offset(frame, np.asarray(p.centre), fov_deg) - target for p in layout.distractors),
                     default=math.inf)
        if (margin <= -FAIR_MARGIN) if crowded else (margin >= FAIR_MARGIN):
            return frame
    return None


def loose_box(mask: np.ndarray, rng: np.random.Generator) -> tuple[int, int, int, int]:
    """(x, y, width, height) of a box around ``mask`` (H, W) bool as a detector gives it: its tight box grown on
    each side by a random ``LOOSE_BOX`` share of the box's size, clipped to the image."""
    rows, cols = np.nonzero(mask)
    top, bottom, left, right = rows.min(), rows.max() + 1, cols.min(), cols.max() + 1
    grow = rng.uniform(*LOOSE_BOX, size=4)
    height, width = bottom - top, right - left
    top, bottom = max(0, int(top - grow[0] * height)), min(mask.shape[0], int(bottom + grow[1] * height))
    left, right = max(0, int(left - grow[2] * width)), min(mask.shape[1], int(right + grow[3] * width))
    return left, top, right - left, bottom - top


def stereo_depth(depth: np.ndarray, rng: np.random.Generator, sd_at_1m: float = STEREO_SD_AT_1M,
                 edge_jump: float = STEREO_EDGE_JUMP, edge_px: int = STEREO_EDGE_PX) -> np.ndarray:
    """A rendered depth (H, W) m as an active stereo camera (a RealSense D4xx) reads it: Gaussian noise whose
    standard deviation grows with the square of the depth (``sd_at_1m`` m at 1 m: stereo's depth error goes as
    z^2 / (focal x baseline)), and no reading (0) on the far side of a depth edge: within ``edge_px`` px of a
    surface more than ``edge_jump`` of the depth nearer, where the pair's second camera cannot see past it;
    rounded to whole millimetres as a 16UC1 image stores it."""
    z = np.asarray(depth, dtype=np.float32)
    noisy = z + sd_at_1m * z.astype(np.float64) ** 2 * rng.standard_normal(z.shape)
    nearest_around = cv2.erode(z, np.ones((2 * edge_px + 1,) * 2, np.uint8))
    shadow = z > nearest_around * (1.0 + edge_jump)
    return np.where(shadow, 0.0, np.round(noisy * 1000.0) / 1000.0).astype(np.float32)


def sensor_depth(depth: np.ndarray, rng: np.random.Generator, relative_sd: float) -> np.ndarray:
    """A rendered depth (H, W) m as a depth camera reads it: Gaussian noise of ``relative_sd`` of each reading
    (stereo noise grows with distance), then rounded to whole millimetres as a 16UC1 image stores it."""
    noisy = depth * (1.0 + relative_sd * rng.standard_normal(depth.shape))
    return (np.round(noisy * 1000.0) / 1000.0).astype(np.float32)
