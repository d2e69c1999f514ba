"""Depth-comparison features: hand computations, background and off-image probes, scaling."""

from __future__ import annotations

import numpy as np
import pytest

from posedrift.camera import Intrinsics
from posedrift.labelling import depth_features
from posedrift.labelling._features import pair_features, pixel_terms, probe_image

CAM = Intrinsics(fx=100.0, fy=100.0, cx=3.0, cy=2.5, width=6, height=5)


def _image() -> np.ndarray:
    depth = np.arange(30, dtype=np.float32).reshape(5, 6) / 10.0 + 1.0  # 1.0 .. 3.9 m
    depth[4, 5] = 0.0  # no measurement
    return depth


def test_features_match_a_hand_computation():
    depth = _image()
    d = depth[2, 1]  # 2.3 m at (row 2, col 1)
    # u: 2 columns right at this depth, v: 1 row down; offsets are pixel x metres.
    offsets = np.array([[0.0, 2.0 * d, 1.0 * d, 0.0], [1.0 * d, -1.0 * d, 0.0, 0.0]])
    got = depth_features(depth, [[2, 1]], offsets, intrinsics=CAM, reference_focal=100.0)
    expected = [depth[2, 3] - depth[3, 1], depth[3, 0] - depth[2, 1]]
    np.testing.assert_allclose(got[0], expected, atol=1e-6)
    assert got.dtype == np.float32 and got.shape == (1, 2)


def test_probes_round_half_up_to_the_nearest_pixel():
    depth = np.full((5, 6), 2.0, dtype=np.float32)
    depth[:, 3] = 3.0
    # 1.5 columns right of column 1 -> column 2.5 -> rounds up to column 3.
    offsets = np.array([[0.0, 3.0, 0.0, 0.0], [0.0, 2.98, 0.0, 0.0]])
    got = depth_features(depth, [[1, 1]], offsets, intrinsics=CAM, reference_focal=100.0)
    np.testing.assert_allclose(got[0], [1.0, 0.0])


def test_off_image_and_background_probes_read_the_constant():
    depth = _image()
    mask = np.ones((5, 6), dtype=bool)
    mask[0, 0] = False  # background
    pixel = [[2, 2]]
    d = float(depth[2, 2])
    offsets = np.array(
        [
            [-2.0 * d, -2.0 * d, 0.0, 0.0],  # (0, 0): background by the mask
            [0.0, 50.0 * d, 0.0, 0.0],  # far right: off the image
            [-9.0 * d, 0.0, 0.0, 0.0],  # above the image
            [2.0 * d, 3.0 * d, 0.0, 0.0],  # (4, 5): no depth measurement
        ]
    )
    got = depth_features(
        depth, pixel, offsets, intrinsics=CAM, mask=mask, reference_focal=100.0, background=10.0
    )
    np.testing.assert_allclose(got[0], 10.0 - d, atol=1e-6)


def test_offsets_scale_with_the_focal_length():
    depth = np.full((10, 12), 2.0, dtype=np.float32)
    depth[:, 6:] = 4.0
    # At f = f_ref an offset of 4 pixel x m at 2 m moves 2 columns; at 2 f_ref, 4 columns.
    offsets = np.array([[0.0, 4.0, 0.0, 0.0]])
    cam = Intrinsics(fx=100.0, fy=100.0, cx=6.0, cy=5.0, width=12, height=10)
    at_ref = depth_features(depth, [[5, 2]], offsets, intrinsics=cam, reference_focal=100.0)
    doubled = depth_features(depth, [[5, 2]], offsets, intrinsics=cam, reference_focal=50.0)
    assert at_ref[0, 0] == 0.0 and doubled[0, 0] == 2.0


def test_per_pixel_kernel_equals_the_training_matrix_bitwise():
    rng = np.random.default_rng(3)
    depth = rng.uniform(1.5, 4.0, size=(40, 50)).astype(np.float32)
    mask = rng.uniform(size=depth.shape) < 0.8
    cam = Intrinsics(fx=90.0, fy=95.0, cx=25.0, cy=20.0, width=50, height=40)
    rows, cols = np.nonzero(mask)
    pixels = np.column_stack([rows, cols])[:300]
    offsets = rng.uniform(-150, 150, size=(64, 4))
    matrix = depth_features(depth, pixels, offsets, intrinsics=cam, mask=mask)
    image = probe_image(depth, mask, 10.0)
    terms = pixel_terms(depth, pixels, cam, 285.63)
    choice = rng.integers(len(offsets), size=len(pixels))
    single = pair_features(image, depth.shape, *terms, offsets.astype(np.float32)[choice])
    np.testing.assert_array_equal(single, matrix[np.arange(len(pixels)), choice])


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"pixels": [[4, 5]]}, "foreground pixels with positive depth"),
        ({"pixels": [[7, 0]]}, "foreground pixels with positive depth"),
        ({"pixels": [[1.0, 2.0]]}, "integer array"),
        ({"offsets": np.zeros((3, 2))}, "'offsets'"),
        ({"depth": np.ones((4, 4))}, "'depth'"),
        ({"mask": np.ones((2, 2), bool)}, "'mask'"),
    ],
)
def test_bad_arguments_are_named(kwargs, match):
    args = {"depth": _image(), "pixels": [[1, 1]], "offsets": np.zeros((2, 4))}
    args.update(kwargs)
    depth, pixels, offsets = args.pop("depth"), args.pop("pixels"), args.pop("offsets")
    with pytest.raises(ValueError, match=match):
        depth_features(depth, pixels, offsets, intrinsics=CAM, **args)


def test_compiled_feature_matrix_equals_the_numpy_loop_bitwise():
    from posedrift.labelling import _features

    if _features._ckernels is None:
        pytest.skip("the compiled kernels (posedrift.labelling._ckernels) are not built")
    rng = np.random.default_rng(4)
    depth = rng.uniform(1.5, 4.0, size=(40, 50)).astype(np.float32)
    depth[rng.uniform(size=depth.shape) < 0.05] = 0.0  # holes
    mask = (rng.uniform(size=depth.shape) < 0.8) & (depth > 0)
    cam = Intrinsics(fx=90.0, fy=95.0, cx=25.0, cy=20.0, width=50, height=40)
    pixels = np.argwhere(mask)[:500]
    offsets = rng.uniform(-400, 400, size=(300, 4)).astype(np.float32)  # many off the image
    options = {"reference_focal": 285.63, "background": 10.0}
    compiled = _features.feature_matrix(depth, mask, pixels, offsets, cam, **options)
    loop = _features.feature_matrix(depth, mask, pixels, offsets, cam, compiled=False, **options)
    np.testing.assert_array_equal(compiled, loop)
    assert np.any(compiled > 5.0) and np.any(compiled < -5.0)  # background probes both ways
