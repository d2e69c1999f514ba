"""Person segmentation and uniform downsampling."""

from __future__ import annotations

import numpy as np
import pytest

from posedrift.camera import CameraPose, DepthFrame, backproject, camera_preset
from posedrift.points import (
    BackgroundModel,
    downsample,
    fit_floor_plane,
    sample_humanoid,
    segment_person,
)
from posedrift.skeleton import t_pose_joints

K = camera_preset("kinect1-qvga")


def _person_depth(distance: float = 2.8, n: int = 60000) -> np.ndarray:
    """Z-buffered splat of a capsule body standing on the floor (y = 0), facing the camera."""
    cam = CameraPose.look_at(eye=(0.0, 1.0, distance), target=(0.0, 1.0, 0.0))
    pts = cam.world_to_camera(sample_humanoid(t_pose_joints(1.75), n, rng=0))
    u = np.round(K.fx * pts[:, 0] / pts[:, 2] + K.cx).astype(int)
    v = np.round(K.fy * pts[:, 1] / pts[:, 2] + K.cy).astype(int)
    ok = (u >= 0) & (u < K.width) & (v >= 0) & (v < K.height)
    depth = np.full(K.shape, np.inf)
    np.minimum.at(depth, (v[ok], u[ok]), pts[ok, 2])
    depth[~np.isfinite(depth)] = 0.0
    return depth.astype(np.float32), cam


def _scene(person: np.ndarray, cam: CameraPose) -> np.ndarray:
    """The person in front of a wall at 4.5 m and above a floor plane (y = 0)."""
    rows, cols = np.mgrid[0 : K.height, 0 : K.width]
    rays = np.stack([(cols - K.cx) / K.fx, (rows - K.cy) / K.fy, np.ones(K.shape)], -1)
    # Floor y_world = 0: camera centre is 1 m above it, +Y down in the camera frame.
    up_cam = cam.rotation @ np.array([0.0, 1.0, 0.0])
    down = -(rays @ up_cam)  # > 0 for rays that go down towards the floor
    with np.errstate(divide="ignore"):
        t_floor = np.where(down > 1e-6, 1.0 / down, np.inf)
    wall = np.full(K.shape, 4.5)
    scene = np.minimum(wall, t_floor * rays[..., 2])
    scene = np.where(person > 0, np.minimum(person, scene), scene)
    return scene.astype(np.float32)


@pytest.fixture(scope="module")
def rendered():
    """Rendered frames of the built-in motion: a bare one and one in a room (floor, wall)."""
    from posedrift.synthetic import build_sequence, procedural_motion

    motion = procedural_motion()
    bare = build_sequence(motion, n_frames=1, rng=0)
    room = build_sequence(motion, n_frames=1, background=True, rng=0)
    return bare, room


def _scores(mask: np.ndarray, truth: np.ndarray) -> tuple[float, float]:
    hit = (mask & truth).sum()
    return hit / truth.sum(), hit / max(mask.sum(), 1)


def test_segment_synthetic_frame_keeps_the_person(rendered):
    bare, _ = rendered
    truth = bare.reference.labels[0] > 0
    recall, precision = _scores(segment_person(bare.frames[0]), truth)
    assert recall > 0.99
    assert precision > 0.99


def test_segment_room_removes_floor_and_wall(rendered):
    _, room = rendered
    frame = room.frames[0]
    truth = room.reference.labels[0] > 0
    assert (frame.depth[~truth] > 0).sum() > 5 * truth.sum()  # the room is really there
    recall, precision = _scores(segment_person(frame), truth)
    assert recall > 0.97
    assert precision > 0.97


def test_segment_splat_scene_with_floor_and_wall():
    person, cam = _person_depth()
    scene = _scene(person, cam)
    mask = segment_person(DepthFrame(scene, K), max_depth=4.0)
    recall, precision = _scores(mask, person > 0)
    assert recall > 0.9
    assert precision > 0.95


def test_background_model_separates_person_from_static_scene():
    person, cam = _person_depth()
    empty = _scene(np.zeros_like(person), cam)
    model = BackgroundModel(margin=0.1).fit([empty, empty, empty])
    mask = segment_person(_scene(person, cam), K, background=model, remove_floor=False)
    recall, precision = _scores(mask, person > 0)
    assert recall > 0.9
    assert precision > 0.95
    with pytest.raises(ValueError, match="not fitted"):
        BackgroundModel().foreground(empty)
    with pytest.raises(ValueError, match="background's shape"):
        model.foreground(np.zeros((3, 3)))


def test_segment_empty_and_nan_frames_give_no_person():
    assert not segment_person(np.zeros(K.shape, np.float32), K).any()
    nan = np.full(K.shape, np.nan, np.float32)
    assert not segment_person(nan, K).any()
    small = np.zeros(K.shape, np.float32)
    small[100:105, 100:105] = 2.0  # 25 pixels: too small to be a person
    assert not segment_person(small, K).any()


def test_segment_rejects_bad_shape():
    with pytest.raises(ValueError, match="2-D depth image"):
        segment_person(np.zeros((3, 4, 5)), K)


def test_floor_plane_ransac_finds_the_floor():
    rng = np.random.default_rng(0)
    floor = np.column_stack(
        [rng.uniform(-2, 2, 3000), np.full(3000, 1.0), rng.uniform(1, 5, 3000)]
    )  # camera 1 m above a level floor: y = +1 in the camera frame
    floor[:, 1] += rng.normal(scale=0.005, size=3000)
    normal, offset = fit_floor_plane(floor, rng=0)
    assert abs(normal @ np.array([0.0, -1.0, 0.0])) > 0.999
    assert abs(offset - 1.0) < 0.01  # n . x + d = 0 with n = -Y: -1 + d = 0
    wall = np.column_stack([rng.uniform(-2, 2, 3000), rng.uniform(-1, 1, 3000), np.full(3000, 4)])
    assert fit_floor_plane(wall, rng=0) is None


def test_downsample_count_density_and_determinism():
    depth, _ = _person_depth()
    full, _ = backproject(depth, K)
    a = downsample(full, 400, rng=3)
    b = downsample(full, 400, rng=3)
    assert a.shape == (400, 3)
    np.testing.assert_array_equal(a, b)
    # Even density: nearest-neighbour spacings vary little (no clumps, few holes).
    from scipy.spatial import cKDTree

    d, _ = cKDTree(a).query(a, k=2)
    spacing = d[:, 1]
    assert np.percentile(spacing, 90) < 2.0 * np.median(spacing)
    # Every sample lies on the surface (within a voxel of an input point).
    dd, _ = cKDTree(full).query(a)
    assert dd.max() < 0.05


def test_downsample_small_input_and_errors():
    pts = np.random.default_rng(0).normal(size=(50, 3))
    np.testing.assert_array_equal(downsample(pts, 400), pts)
    with pytest.raises(ValueError, match="'n' parameter of downsample"):
        downsample(pts, 0)
    with pytest.raises(ValueError, match="'points' argument of downsample"):
        downsample(np.zeros((5, 2)), 3)
