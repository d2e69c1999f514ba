import numpy as np
import pytest

from posedrift.camera import (
    CAMERA_PRESETS,
    CameraPose,
    DepthFrame,
    Intrinsics,
    backproject,
    camera_preset,
    parse_intrinsics,
    project,
)


def test_backproject_project_round_trip():
    k = camera_preset("kinect1-qvga")
    rng = np.random.default_rng(1)
    depth = rng.uniform(1.0, 4.0, size=k.shape)
    depth[::7, ::5] = 0.0
    points, pixels = backproject(depth, k)
    uv = project(points, k)
    np.testing.assert_allclose(uv[:, 0], pixels[:, 1], atol=1e-9)
    np.testing.assert_allclose(uv[:, 1], pixels[:, 0], atol=1e-9)
    assert len(points) == np.count_nonzero(depth)


def test_principal_point_maps_to_optical_axis():
    k = Intrinsics(fx=500, fy=500, cx=10, cy=20, width=40, height=30)
    depth = np.zeros(k.shape)
    depth[20, 10] = 2.5
    points, _ = backproject(depth, k)
    np.testing.assert_allclose(points, [[0.0, 0.0, 2.5]])


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"fx": -1}, "'fx'"),
        ({"cx": 500}, "'cx'.*inside the image"),
        ({"height": 0}, "'height'"),
    ],
)
def test_invalid_intrinsics_name_the_field(kwargs, match):
    base = {"fx": 285.63, "fy": 285.63, "cx": 160, "cy": 120, "width": 320, "height": 240}
    with pytest.raises(ValueError, match=match):
        Intrinsics(**(base | kwargs))


def test_unknown_preset_lists_choices():
    with pytest.raises(ValueError, match="kinect1-vga.*d435"):
        camera_preset("kinect9")
    assert set(CAMERA_PRESETS) >= {"kinect1-vga", "kinect1-qvga", "kinect2", "d435"}


def test_parse_intrinsics():
    k = parse_intrinsics("285.63, 285.63,160,120", width=320, height=240)
    assert k == camera_preset("kinect1-qvga")
    with pytest.raises(ValueError, match="fx,fy,cx,cy"):
        parse_intrinsics("1,2,3", width=320, height=240)


def test_look_at_puts_target_on_axis_and_up_up():
    pose = CameraPose.look_at(eye=[0.0, 1.0, 3.0], target=[0.0, 1.0, 0.0])
    np.testing.assert_allclose(pose.world_to_camera([0.0, 1.0, 0.0]), [0, 0, 3.0], atol=1e-12)
    above = pose.world_to_camera([0.0, 2.0, 0.0])
    assert above[1] < 0  # image +Y is down
    np.testing.assert_allclose(
        pose.camera_to_world(pose.world_to_camera([1.0, 2.0, 3.0])), [1, 2, 3]
    )


def test_depth_frame_sanitises_and_validates():
    k = camera_preset("kinect1-qvga")
    raw = np.full(k.shape, 2000, dtype=np.uint16)
    frame = DepthFrame.from_raw(raw, k, index=3)
    assert frame.depth.dtype == np.float32 and frame.depth[0, 0] == pytest.approx(2.0)
    bad = np.full(k.shape, np.nan)
    assert DepthFrame(bad, k).depth.max() == 0.0
    with pytest.raises(ValueError, match="frame 7.*shape \\(240, 320\\)"):
        DepthFrame(np.zeros((10, 10)), k, index=7)
    with pytest.raises(ValueError, match="depth_scale"):
        DepthFrame.from_raw(raw, k, depth_scale=0)


def _reference_backproject(depth, intrinsics, mask=None):
    """The original backproject (2-D np.nonzero), kept to check the fast one bit for bit."""
    depth = np.asarray(depth)
    valid = np.isfinite(depth) & (depth > 0)
    if mask is not None:
        valid &= np.asarray(mask, dtype=bool)
    rows, cols = np.nonzero(valid)
    z = depth[rows, cols].astype(float)
    x = (cols - intrinsics.cx) * z / intrinsics.fx
    y = (rows - intrinsics.cy) * z / intrinsics.fy
    return np.column_stack([x, y, z]), np.column_stack([rows, cols])


@pytest.mark.parametrize("dtype", [np.float32, np.float64, np.uint16])
def test_backproject_matches_the_original_bit_for_bit(dtype):
    k = Intrinsics(fx=365.5, fy=364.1, cx=255.3, cy=211.7, width=512, height=424)
    rng = np.random.default_rng(2)
    depth = rng.uniform(0.5, 6.0, size=k.shape)
    depth[rng.random(k.shape) < 0.3] = 0.0
    if dtype is not np.uint16:
        depth[rng.random(k.shape) < 0.05] = np.nan
        depth[rng.random(k.shape) < 0.01] = np.inf
    depth = depth.astype(dtype) if dtype is not np.uint16 else (depth * 1000).astype(dtype)
    mask = rng.random(k.shape) < 0.7
    # A non-contiguous view (every other row of a taller image) too.
    tall = np.repeat(depth, 2, axis=0)[::2]
    for image in (depth, tall):
        for m in (None, mask):
            new, ref = backproject(image, k, m), _reference_backproject(image, k, m)
            for a, b in zip(new, ref, strict=True):
                assert a.dtype == b.dtype
                np.testing.assert_array_equal(a, b, strict=True)
    empty = backproject(np.zeros(k.shape), k)
    assert empty[0].shape == (0, 3) and empty[1].shape == (0, 2)
