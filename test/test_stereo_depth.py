"""The synthetic stereo depth: noise that grows with the square of the depth, holes only on the far side of a depth
edge, millimetre steps."""
import numpy as np

from idpose_core.synthetic.tabletop import stereo_depth


def test_noise_grows_with_depth_squared():
    rng = np.random.default_rng(0)
    spreads = [np.std(stereo_depth(np.full((200, 200), z, np.float32), rng, sd_at_1m=0.004) - z) for z in (0.5, 2.0)]
    assert spreads[0] < 0.0015 and 0.014 < spreads[1] < 0.018, spreads  # 1 mm at 0.5 m (+ rounding), 16 mm at 2 m


def test_holes_lie_on_the_far_side_of_an_edge_and_readings_are_whole_millimetres():
    depth = np.full((40, 40), 1.0, np.float32)
    depth[:, :20] = 0.5  # a near surface on the left, the background on the right
    read = stereo_depth(depth, np.random.default_rng(1), sd_at_1m=0.0, edge_px=2)
    holes = read == 0.0
    assert holes[:, 20:22].all() and not holes[:, 22:].any(), "2 px of background beside the near surface"
    assert not holes[:, :20].any(), "the near surface keeps its readings"
    np.testing.assert_allclose(read[~holes] * 1000.0, np.round(read[~holes] * 1000.0), atol=1e-3)
