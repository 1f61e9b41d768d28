"""Preprocessing on the reference photos: masks (alpha, threshold, GrabCut), one window per set, white margins."""
from pathlib import Path

import cv2
import numpy as np
import pytest

from idpose_core.preprocessing import (
    MIN_IMAGE_SIDE,
    PreprocessingError,
    bounding_box,
    precheck_view,
    preprocess_views,
)
from idpose_core.view_input import ViewInput


def prep(rgbs, alphas, **options):
    """preprocess_views on views made of these images and alpha channels."""
    return preprocess_views([ViewInput(rgb, alpha) for rgb, alpha in zip(rgbs, alphas)], **options)

DATA = Path(__file__).resolve().parents[2] / "shared" / "reference" / "idpose-official" / "data"
REAL_OBJECTS = ["chair_photo", "foosball_photo", "toyduck_photo"]
# Lion body boxes (x0, y0, x1, y1) read by eye off the full-resolution JPEGs (paws to mane, no shadow).
LION_BOXES = {"000.jpg": (408, 263, 625, 495), "001.jpg": (460, 165, 612, 435)}


def load(path: Path) -> tuple[np.ndarray, np.ndarray | None]:
    """(RGB uint8, alpha uint8 or None) of an image file."""
    image = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if image.shape[2] == 4:
        return np.ascontiguousarray(cv2.cvtColor(image, cv2.COLOR_BGRA2RGB)), np.ascontiguousarray(image[..., 3])
    return np.ascontiguousarray(cv2.cvtColor(image, cv2.COLOR_BGR2RGB)), None


def load_set(pattern: str) -> tuple[list, list]:
    files = sorted(DATA.glob(pattern))
    if not files:
        pytest.skip(f"reference images {pattern} not found under {DATA}")
    views = [load(f) for f in files]
    return [v[0] for v in views], [v[1] for v in views]


def object_box(image) -> tuple[int, int, int, int]:
    """(x, y, w, h) of the non-white pixels of a preprocessed view (3, S, S) in [-1, 1]."""
    pixels = ((image.permute(1, 2, 0).numpy() + 1.0) * 127.5).round()
    return bounding_box((pixels < 250).any(axis=-1))


def assert_centred_same_scale_white_margins(result, size=256, window_scale=1.5):
    """Every view: object centred, scale = size / shared window side, outer margin pure white."""
    images = result.images
    assert images.shape == (len(result.masks), 3, size, size) and str(images.dtype) == "torch.float32"
    assert images.min() >= -1.0 and images.max() <= 1.0
    sides = {window[2] for window in result.windows}
    assert len(sides) == 1, f"views cropped with different windows {result.windows}"
    scale = size / sides.pop()
    input_sides = [max(bounding_box(mask)[2:]) for mask in result.masks]
    margin = int(size * (1 - 1 / window_scale) / 2) - 4  # room the largest object leaves, less blur
    for index, (image, input_side) in enumerate(zip(images, input_sides)):
        x, y, w, h = object_box(image)
        assert abs(x + w / 2 - size / 2) <= 3 and abs(y + h / 2 - size / 2) <= 3, f"view {index} off centre"
        assert abs(max(w, h) - input_side * scale) <= 3, f"view {index} at another scale"
        band = np.ones((size, size), dtype=bool)
        band[margin:-margin, margin:-margin] = False
        assert np.all(image.numpy()[:, band] == 1.0), f"view {index} margin not white"
    largest = max(max(object_box(image)[2:]) for image in images)
    assert abs(largest - size / window_scale) <= 3


@pytest.mark.parametrize("name", REAL_OBJECTS)
def test_real_rgba_photos_use_alpha_and_share_one_window(name):
    rgbs, alphas = load_set(f"real/{name}/images/*.png")
    result = prep(rgbs, alphas)
    assert result.mask_methods == ["alpha"] * len(rgbs)
    for mask, alpha in zip(result.masks, alphas):
        np.testing.assert_array_equal(mask, alpha > 127)
    assert_centred_same_scale_white_margins(result)


def test_lion_photos_with_background_are_cut_out_by_grabcut():
    rgbs, alphas = load_set("demo/lion/*.jpg")
    result = prep(rgbs, alphas)
    assert result.mask_methods == ["grabcut", "grabcut"]
    for (name, (x0, y0, x1, y1)), mask in zip(sorted(LION_BOXES.items()), result.masks):
        assert mask.mean() < 0.1, f"{name}: mask covers {mask.mean():.0%} of the photo, not just the lion"
        x, y, w, h = bounding_box(mask)
        assert x <= x0 + 10 and y <= y0 + 10 and x + w >= x1 - 10 and y + h >= y1 - 10, f"{name}: lion cut"
        overlap = max(0, min(x1, x + w) - max(x0, x)) * max(0, min(y1, y + h) - max(y0, y))
        union = (x1 - x0) * (y1 - y0) + w * h - overlap
        assert overlap / union > 0.6, f"{name}: mask box {x, y, w, h} strays from the lion"
    assert_centred_same_scale_white_margins(result)


@pytest.mark.parametrize("name", REAL_OBJECTS)
def test_uniform_background_is_thresholded(name):
    """The RGBA photos composited on a plain, slightly noisy colour and given without alpha."""
    rgbs, alphas = load_set(f"real/{name}/images/*.png")
    rng = np.random.default_rng(0)
    plain = []
    for rgb, alpha in zip(rgbs, alphas):
        background = np.array([90.0, 140.0, 200.0]) + rng.normal(0.0, 2.0, rgb.shape)
        plain.append(np.where((alpha > 127)[..., None], rgb, background).clip(0, 255).astype(np.uint8))
    result = prep(plain, [None] * len(plain))
    assert result.mask_methods == ["threshold"] * len(plain)
    for index, (mask, alpha) in enumerate(zip(result.masks, alphas)):
        truth = alpha > 127
        iou = (mask & truth).sum() / (mask | truth).sum()
        assert iou > 0.85, f"view {index}: IoU {iou:.3f} with the alpha mask"
    assert_centred_same_scale_white_margins(result)


def test_fully_opaque_alpha_carries_no_mask():
    rgb = np.full((64, 64, 3), 255, dtype=np.uint8)
    rgb[20:40, 24:44] = (200, 30, 30)
    result = prep([rgb], [np.full((64, 64), 255, dtype=np.uint8)])
    assert result.mask_methods == ["threshold"]
    assert bounding_box(result.masks[0]) == (24, 20, 20, 20)


def test_window_leaving_the_image_is_padded_white():
    """A red square in the corner: the window reaches past the image edge and the object still sits centred."""
    rgb = np.full((100, 120, 3), 255, dtype=np.uint8)
    rgb[:30, :30] = (255, 0, 0)
    result = prep([rgb], [None], size=64)
    x, y, side = result.windows[0]
    assert (x, y, side) == (-8, -8, 45)
    image = result.images[0].numpy()
    np.testing.assert_allclose(image[:, 32, 32], [1.0, -1.0, -1.0])
    assert np.all(image[:, :5] == 1.0) and np.all(image[:, :, :5] == 1.0)
    assert_centred_same_scale_white_margins(result, size=64)


def test_smaller_view_keeps_its_size_relative_to_the_largest():
    """Two squares of 40 and 20 px: the window is 60 px for both, so the small one fills a third of the output."""
    big = np.full((100, 100, 3), 255, dtype=np.uint8)
    big[30:70, 30:70] = (0, 0, 255)
    small = np.full((100, 100, 3), 255, dtype=np.uint8)
    small[10:30, 60:80] = (0, 128, 0)
    result = prep([big, small], [None, None], size=60)
    assert [w[2] for w in result.windows] == [60, 60]
    assert max(object_box(result.images[1])[2:]) == 20
    assert_centred_same_scale_white_margins(result, size=60)


def test_empty_masks_name_the_view():
    object_view = np.full((64, 64, 3), 255, dtype=np.uint8)
    object_view[20:40, 20:40] = 0
    blank = np.full((64, 64, 3), 255, dtype=np.uint8)
    with pytest.raises(PreprocessingError, match="view 1: no object found"):
        prep([object_view, blank], [None, None])
    with pytest.raises(PreprocessingError, match=r"view 0: no object found \(empty alpha mask\)"):
        prep([object_view], [np.zeros((64, 64), dtype=np.uint8)])


@pytest.mark.parametrize(
    "rgbs, alphas, message",
    [
        ([np.zeros((64, 64, 3), np.float32)], [None], "view 0: expected an RGB uint8"),
        ([np.zeros((64, 64), np.uint8)], [None], "view 0: expected an RGB uint8"),
        ([np.zeros((64, 64, 3), np.uint8)], [np.zeros((32, 32), np.uint8)], "view 0: alpha must be uint8"),
        ([], [], "no views to preprocess"),
    ],
)
def test_malformed_input_is_rejected(rgbs, alphas, message):
    with pytest.raises(PreprocessingError, match=message):
        prep(rgbs, alphas)


def square_on_white(side: int, square: int) -> np.ndarray:
    rgb = np.full((side, side, 3), 255, dtype=np.uint8)
    start = (side - square) // 2
    rgb[start:start + square, start:start + square] = (30, 90, 200)
    return rgb


@pytest.mark.parametrize("size", [64, 256, 480])
def test_pure_noise_has_no_object(size):
    noise = np.random.default_rng(size).integers(0, 256, (size, size, 3), dtype=np.uint8)
    with pytest.raises(PreprocessingError, match=r"view 1: no object found \(empty grabcut mask\)"):
        prep([square_on_white(64, 30), noise], [None, None])


@pytest.mark.parametrize("rgb, alpha, message", [
    (square_on_white(8, 4), None, r"view 0 is 8x8 px, too small \(at least 32 px a side\)"),
    (square_on_white(64, 10), None, r"view 0: the object \(threshold mask\) is only 10x10 px, too small"),
    (square_on_white(64, 30), np.pad(np.full((62, 62), 255, np.uint8), 1),
     r"view 0: the alpha mask covers 94% of the frame \(at most 90%\): no object separated"),
], ids=["8x8-image", "speck", "whole-frame"])
def test_implausible_views_are_refused_with_the_reason(rgb, alpha, message):
    with pytest.raises(PreprocessingError, match=message):
        prep([rgb], [alpha])


def test_the_cheap_precheck_refuses_what_needs_no_computed_mask():
    precheck_view(ViewInput(square_on_white(MIN_IMAGE_SIDE, 16)), "the image")  # smallest plausible view
    with pytest.raises(PreprocessingError, match="the image is 31x31 px, too small"):
        precheck_view(ViewInput(square_on_white(MIN_IMAGE_SIDE - 1, 16)), "the image")
    speck = np.zeros((64, 64), np.uint8)
    speck[30:35, 30:35] = 255
    with pytest.raises(PreprocessingError, match=r"the image: the object \(alpha mask\) is only 5x5 px"):
        precheck_view(ViewInput(square_on_white(64, 30), speck), "the image")
    noise = np.random.default_rng(0).integers(0, 256, (64, 64, 3), dtype=np.uint8)
    precheck_view(ViewInput(noise), "the image")  # without alpha the mask is computed later, by preprocess_views
