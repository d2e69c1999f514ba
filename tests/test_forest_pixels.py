"""BodyPartForest.predict_pixels: the forest's probabilities at chosen pixels only."""

from __future__ import annotations

import numpy as np
import pytest

from posedrift.camera import camera_preset
from posedrift.labelling import BodyPartForest

K = camera_preset("kinect1-qvga")


@pytest.fixture(scope="module")
def frame():
    from posedrift.synthetic import build_sequence, procedural_motion

    return build_sequence(procedural_motion(), n_frames=31, rng=0).frames[30]


def test_equals_predict_at_those_pixels(frame):
    forest = BodyPartForest.load_default()
    mask = frame.depth > 0
    mask[: K.shape[0] // 2, : K.shape[1] // 2] = False  # probes read background here too
    pred = forest.predict(frame.depth, mask, K)
    pick = np.random.default_rng(0).choice(len(pred.pixels), 300, replace=False)
    probs = forest.predict_pixels(frame.depth, pred.pixels[pick], K, mask=mask)
    assert probs.dtype == np.float32 and probs.shape == (300, 15)
    np.testing.assert_array_equal(probs, pred.probabilities[pick])
    # Without a mask: every pixel with depth, as predict(depth, None, ...).
    full = forest.predict(frame.depth, None, K)
    np.testing.assert_array_equal(
        forest.predict_pixels(frame.depth, full.pixels[::50], K), full.probabilities[::50]
    )


def test_background_pixels_get_a_uniform_row(frame):
    forest = BodyPartForest.load_default()
    probs = forest.predict_pixels(frame.depth, np.array([[0, 0], [1, 1]]), K)
    np.testing.assert_allclose(probs, 1.0 / 15)
    assert forest.predict_pixels(frame.depth, np.zeros((0, 2), int), K).shape == (0, 15)


def test_rejects_bad_arguments(frame):
    forest = BodyPartForest.load_default()
    with pytest.raises(ValueError, match="'pixels'.*inside"):
        forest.predict_pixels(frame.depth, np.array([[240, 0]]), K)
    with pytest.raises(ValueError, match="'pixels'.*integer"):
        forest.predict_pixels(frame.depth, np.array([[1.0, 2.0]]), K)
    with pytest.raises(ValueError, match="'depth'"):
        forest.predict_pixels(np.zeros((10, 10)), np.array([[1, 1]]), K)
    with pytest.raises(ValueError, match="'mask'"):
        forest.predict_pixels(frame.depth, np.array([[1, 1]]), K, mask=np.ones((3, 3), bool))
    with pytest.raises(ValueError, match="'intrinsics'"):
        forest.predict_pixels(frame.depth, np.array([[1, 1]]), "kinect")
