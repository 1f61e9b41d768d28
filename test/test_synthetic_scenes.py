"""Synthetic scenes: object sets, TinyRenderer renders on white with masks, camera sampling (small renders)."""
import math

import numpy as np
import pytest

from idpose_core.synthetic.scenes import (
    CAMERA_RADIUS,
    TRAINING_LIGHT,
    ObjectSpec,
    SceneRenderer,
    camera_up,
    demo_objects,
    oracle_objects,
    random_camera_spheres,
    random_light,
    symmetric_objects,
)

SIZE = 64
POSES_DEG = [(0.0, 0.0), (30.0, 10.0), (90.0, 200.0), (150.0, 300.0), (180.0, 45.0)]


def all_objects() -> list[ObjectSpec]:
    return demo_objects() + oracle_objects() + symmetric_objects()


def test_object_sets_have_the_promised_sizes_and_distinct_names():
    names = [spec.name for spec in all_objects()]
    assert 4 <= len(demo_objects()) <= 8
    assert len(oracle_objects()) >= 10
    assert len(names) == len(set(names)), "object names must be unique across sets"
    assert all(spec.symmetric for spec in symmetric_objects())
    assert not any(spec.symmetric for spec in demo_objects() + oracle_objects())


def test_object_sets_are_fixed():
    assert demo_objects() == demo_objects()
    assert oracle_objects() == oracle_objects()


@pytest.mark.parametrize("spec", all_objects(), ids=lambda spec: spec.name)
def test_every_object_is_whole_in_view_on_white(spec):
    with SceneRenderer(spec, image_size=SIZE) as renderer:
        for polar, azimuth in POSES_DEG:
            rgb, mask = renderer.render(math.radians(polar), math.radians(azimuth))
            assert rgb.shape == (SIZE, SIZE, 3) and rgb.dtype == np.uint8
            assert mask.shape == (SIZE, SIZE) and mask.dtype == bool
            assert 0.02 < mask.mean() < 0.7, f"object covers {mask.mean():.2%} at {polar, azimuth}"
            border = np.concatenate([mask[0], mask[-1], mask[:, 0], mask[:, -1]])
            assert not border.any(), f"{spec.name} leaves the frame at {polar, azimuth}"
            assert (rgb[~mask] == 255).all()
            assert (rgb[mask] < 250).any(axis=-1).mean() > 0.5, "object pixels should not be white"


def test_demo_objects_look_different_from_each_other():
    renders = []
    for spec in demo_objects():
        with SceneRenderer(spec, image_size=SIZE) as renderer:
            renders.append(renderer.render(math.radians(70), math.radians(30))[0].astype(np.float64))
    for a in range(len(renders)):
        for b in range(a + 1, len(renders)):
            assert np.abs(renders[a] - renders[b]).mean() > 5.0


def test_renders_are_deterministic_and_depend_on_the_pose():
    spec = demo_objects()[0]
    with SceneRenderer(spec, image_size=SIZE) as first, SceneRenderer(spec, image_size=SIZE) as second:
        a, _ = first.render(1.0, 2.0)
        b, _ = second.render(1.0, 2.0)
        c, _ = first.render(1.0, 2.5)
    assert np.array_equal(a, b)
    assert not np.array_equal(a, c)


def test_a_light_changes_the_shading_not_the_mask():
    spec = demo_objects()[0]
    with SceneRenderer(spec, image_size=SIZE) as renderer:
        clean, clean_mask = renderer.render(1.0, 2.0)
        assert np.array_equal(renderer.render(1.0, 2.0, light=TRAINING_LIGHT)[0], clean)  # the default
        lit, lit_mask = renderer.render(1.0, 2.0, light=random_light(np.random.default_rng(3)))
    assert np.array_equal(lit_mask, clean_mask)
    assert np.abs(lit[clean_mask].astype(float) - clean[clean_mask]).mean() > 5.0


def test_random_lights_shine_from_above_with_shadows_and_are_seeded():
    lights = [random_light(np.random.default_rng(seed), elevation_deg=(20.0, 60.0)) for seed in range(20)]
    elevations = [math.degrees(math.asin(light.direction[2] / np.linalg.norm(light.direction))) for light in lights]
    assert all(20.0 <= e <= 60.0 for e in elevations) and all(light.shadow for light in lights)
    assert len({light.direction for light in lights}) == 20
    assert random_light(np.random.default_rng(5)) == random_light(np.random.default_rng(5))


def test_half_turn_symmetric_objects_have_half_turn_symmetric_silhouettes():
    for spec in symmetric_objects():
        with SceneRenderer(spec, image_size=SIZE) as renderer:
            for polar, azimuth in [(60.0, 20.0), (100.0, 130.0)]:
                _, mask = renderer.render(math.radians(polar), math.radians(azimuth))
                _, turned = renderer.render(math.radians(polar), math.radians(azimuth + 180.0))
                iou = (mask & turned).sum() / (mask | turned).sum()
                assert iou > 0.9, f"{spec.name}: silhouette IoU {iou:.2f} after a half turn"


def test_camera_up_is_the_projected_vertical_and_stays_valid_at_the_poles():
    for polar, azimuth in [(0.0, 0.3), (math.pi, 1.2), (1.0, 2.0)]:
        up = camera_up(polar, azimuth)
        direction = -np.array([math.sin(polar) * math.cos(azimuth), math.sin(polar) * math.sin(azimuth),
                               math.cos(polar)])
        assert math.isclose(np.linalg.norm(up), 1.0, abs_tol=1e-12)
        assert abs(up @ direction) < 1e-12
        assert up[2] >= 0.0  # never upside down
    # straight above, turning the azimuth turns the image: the render changes
    with SceneRenderer(demo_objects()[0], image_size=SIZE) as renderer:
        assert not np.array_equal(renderer.render(0.0, 0.0)[0], renderer.render(0.0, math.pi / 2)[0])


def test_random_camera_spheres_cover_the_polar_band_and_are_seeded():
    cameras = random_camera_spheres(np.random.default_rng(3), 2000)
    assert cameras.shape == (2000, 3)
    assert np.degrees(cameras[:, 0]).min() >= 30.0 and np.degrees(cameras[:, 0]).max() <= 150.0
    assert (cameras[:, 1] >= 0).all() and (cameras[:, 1] < 2 * math.pi).all()
    assert np.allclose(cameras[:, 2], CAMERA_RADIUS)
    # uniform on the sphere's band: cos(polar) uniform, so the equator is denser than the edges
    assert abs(np.cos(cameras[:, 0]).mean()) < 0.05
    assert np.array_equal(cameras, random_camera_spheres(np.random.default_rng(3), 2000))


def test_bad_arguments_raise_value_errors():
    with pytest.raises(ValueError, match="polar_deg"):
        random_camera_spheres(np.random.default_rng(0), 3, polar_deg=(100.0, 20.0))
    with pytest.raises(ValueError, match="image_size"):
        SceneRenderer(demo_objects()[0], image_size=2)
    with SceneRenderer(demo_objects()[0], image_size=SIZE) as renderer, pytest.raises(ValueError, match="radius"):
        renderer.render(1.0, 1.0, radius=0.5)
