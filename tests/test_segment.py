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


def test_segment_reuses_a_floor_that_still_fits_and_refits_one_that_does_not(rendered):
    _, room = rendered
    frame = room.frames[0]
    plain, floor = segment_person(frame, return_floor=True)
    assert floor is not None and np.array_equal(plain, segment_person(frame))
    normal, offset = floor
    assert normal @ np.array([0.0, -1.0, 0.0]) > 0.95  # level camera: the floor's up is -Y
    # The same plane handed back is kept as it is, and gives the same person.
    again, kept = segment_person(frame, floor=floor, return_floor=True)
    assert kept is floor and np.array_equal(again, plain)
    # A plane 40 cm too high holds no floor points: RANSAC finds the real floor.
    wrong = (normal, offset - 0.4)
    refit, found = segment_person(frame, floor=wrong, return_floor=True)
    assert found is not wrong and np.array_equal(refit, plain)
    # Nothing but floor: no person, and no error.
    points, pixels = backproject(frame.depth, frame.intrinsics, frame.depth > 0)
    on_floor = pixels[np.abs(points @ normal + offset) < 0.02]
    floor_only = np.zeros_like(frame.depth)
    floor_only[on_floor[:, 0], on_floor[:, 1]] = frame.depth[on_floor[:, 0], on_floor[:, 1]]
    assert len(on_floor) > 1000
    empty, _ = segment_person(DepthFrame(floor_only, frame.intrinsics), return_floor=True)
    assert not empty.any()


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


# --------------------------------------------------------------------------- speed rewrites
# Segmentation and downsampling were rewritten for speed; these references are the plain
# versions they replaced (scipy.ndimage morphology, full back-projection before RANSAC,
# np.unique voxels), and the fast ones must agree bit for bit.


def _reference_floor(points, *, threshold=0.03, rng=0):
    up, iterations, min_inliers, min_extent = np.array([0, -1.0, 0]), 60, 200, 1.0
    cos_tilt = np.cos(np.radians(35.0))
    if len(points) < max(3, min_inliers):
        return None
    gen = np.random.default_rng(rng)
    sample = points if len(points) <= 3000 else points[gen.choice(len(points), 3000, replace=False)]
    scale = len(points) / len(sample)
    q = max(3, len(sample) // 4)
    low = np.argpartition(sample @ up, q - 1)[:q]
    if np.ptp(sample[low], axis=0).max() < min_extent:
        return None
    tri = low[gen.integers(0, len(low), size=(iterations, 3))]
    a, b, c = sample[tri[:, 0]], sample[tri[:, 1]], sample[tri[:, 2]]
    normals = np.cross(b - a, c - a)
    norms = np.linalg.norm(normals, axis=1)
    ok = norms > 1e-9
    normals[ok] /= norms[ok, None]
    normals[normals @ up < 0] *= -1
    ok &= normals @ up > cos_tilt
    if not ok.any():
        return None
    normals, a = normals[ok], a[ok]
    offsets = -np.einsum("ij,ij->i", normals, a)
    dist = np.abs(sample @ normals.T + offsets)
    counts = (dist < threshold).sum(axis=0)
    best = int(np.argmax(counts))
    if counts[best] * scale < min_inliers:
        return None
    inl = sample[dist[:, best] < threshold]
    centre = inl.mean(axis=0)
    normal = np.linalg.svd(inl - centre, full_matrices=False)[2][-1]
    normal = -normal if normal @ up < 0 else normal
    if normal @ up < cos_tilt:
        normal, centre = normals[best], a[best]
    if np.ptp(inl - (inl @ normal)[:, None] * normal, axis=0).max() < min_extent:
        return None
    if np.mean(points @ normal - normal @ centre < -2 * threshold) > 0.05:
        return None
    return normal, float(-normal @ centre)


def _reference_segment(frame, *, background=None):
    """segment_person with its default options, as it was written before the speed-up."""
    from scipy import ndimage

    from posedrift.points._segment import _components

    depth = np.where(np.isfinite(frame.depth), frame.depth, 0.0).astype(np.float32)
    mask = (depth >= 0.4) & (depth <= 6.0)
    if background is not None:
        mask &= background.foreground(depth)
    if not mask.any():
        return mask
    if mask.sum() >= 150:
        points, pixels = backproject(depth, frame.intrinsics, mask)
        plane = _reference_floor(points)
        if plane is not None:
            on_floor = points @ plane[0] + plane[1] < 0.03
            mask[pixels[on_floor, 0], pixels[on_floor, 1]] = False
    rows, cols = np.nonzero(mask.any(axis=1))[0], np.nonzero(mask.any(axis=0))[0]
    r0, r1 = max(rows[0] - 3, 0), min(rows[-1] + 4, mask.shape[0])
    c0, c1 = max(cols[0] - 3, 0), min(cols[-1] + 4, mask.shape[1])
    m, d, k = mask[r0:r1, c0:c1], depth[r0:r1, c0:c1], frame.intrinsics
    out = np.zeros_like(mask)
    labels, n = _components(m, d, 0.15)
    counts = np.bincount(labels.ravel(), minlength=n + 1)
    counts[0] = 0
    chosen = 0
    for lab in np.argsort(counts)[::-1][: min(n, 8)]:
        if counts[lab] < 150:
            break
        comp = labels == lab
        rr, cc = np.nonzero(comp.any(axis=1))[0], np.nonzero(comp.any(axis=0))[0]
        z = float(np.median(d[comp]))
        tall, wide = (rr[-1] - rr[0] + 1) * z / k.fy, (cc[-1] - cc[0] + 1) * z / k.fx
        if tall < 0.4 or tall > 2.6 or wide > 2.6:
            continue
        chosen = lab
        break
    if chosen == 0:
        return out
    person = labels == chosen
    z_person = float(np.median(d[person]))
    near = ndimage.binary_dilation(person, iterations=2)
    for lab in np.unique(labels[near & (labels > 0) & ~person]):
        if abs(float(np.median(d[labels == lab])) - z_person) < 0.6:
            person |= labels == lab
    ring = ndimage.binary_dilation(person) & m & (labels == 0)
    if ring.any():
        near_depth = ndimage.grey_dilation(np.where(person, d, 0.0), size=3)
        person |= ring & (np.abs(d - near_depth) < 0.15)
    out[r0:r1, c0:c1] = person
    return out


@pytest.fixture(scope="module")
def varied_frames():
    """Frames with and without floor, wall and sensor noise, and a splatted scene."""
    from posedrift.synthetic import build_sequence, procedural_motion

    motion = procedural_motion()
    frames = list(build_sequence(motion, n_frames=4, rng=0).frames)
    frames += build_sequence(motion, n_frames=6, background=True, noise=True, rng=1).frames
    person, cam = _person_depth()
    frames.append(DepthFrame(_scene(person, cam), K))
    noisy = frames[-2].depth.copy()
    noisy[::7, ::5] = np.nan
    frames.append(DepthFrame(noisy, K))
    return frames


def test_segment_equals_the_reference(varied_frames):
    floors = 0
    for frame in varied_frames:
        assert np.array_equal(segment_person(frame), _reference_segment(frame))
        pts, _ = backproject(frame.depth, K, frame.depth > 0.4)
        got, ref = fit_floor_plane(pts, rng=0), _reference_floor(pts)
        assert (got is None) == (ref is None)
        if ref is not None:
            floors += 1
            assert np.array_equal(got[0], ref[0]) and got[1] == ref[1]
    assert floors >= 3  # the room frames have a floor
    model = BackgroundModel().fit([f.depth for f in varied_frames[4:10]])
    for frame in varied_frames[4:10]:
        assert np.array_equal(
            segment_person(frame, background=model), _reference_segment(frame, background=model)
        )


def test_compiled_components_match_the_numpy_twin(varied_frames):
    from posedrift.points import _segment

    if _segment._cpoints is None:
        pytest.skip("the compiled segmentation kernel is not built (no C compiler at install)")
    rng = np.random.default_rng(2)
    cases = []
    for frame in varied_frames:
        depth = np.nan_to_num(frame.depth).astype(np.float32)
        cases.append((segment_person(frame), depth))
        cases.append(((depth > 0.4) & (depth < 6.0), depth))
    # Steps at the threshold in float32 (1.0 -> 1.15 is 0.14999998), ties, single pixels.
    levels = np.array([1.0, 1.15, 1.3, 1.0000001, 2.0], dtype=np.float32)
    for shape in [(1, 1), (1, 7), (7, 1), (13, 17), (40, 31)]:
        for _ in range(20):
            mask = rng.random(shape) < rng.uniform(0.2, 0.95)
            cases.append((mask, rng.choice(levels, size=shape)))
    for mask, depth in cases:
        got, n_got = _segment._components(mask, depth, 0.15)
        ref, n_ref = _segment._components(mask, depth, 0.15, compiled=False)
        assert n_got == n_ref and got.dtype == ref.dtype and np.array_equal(got, ref)
    # Identity: one flat blob is one component; a step splits it at the farther side.
    depth = np.full((6, 8), 2.0, dtype=np.float32)
    mask = np.ones((6, 8), dtype=bool)
    labels, n = _segment._components(mask, depth, 0.15)
    assert n == 1 and (labels == 1).all()
    depth[:, 4:] = 2.5
    labels, n = _segment._components(mask, depth, 0.15)
    assert n == 2 and (labels[:, :4] == 1).all() and (labels[:, 4] == 0).all()


def test_morphology_kernels_equal_scipy():
    from scipy import ndimage

    from posedrift.points._segment import _dilate, _max3x3, _nonzero

    rng = np.random.default_rng(0)
    for shape in ((1, 1), (1, 7), (6, 1), (23, 31)):
        mask = rng.random(shape) < 0.2
        for it in (1, 2, 3):
            assert np.array_equal(_dilate(mask, it), ndimage.binary_dilation(mask, iterations=it))
        image = rng.random(shape).astype(np.float32) * mask
        assert np.array_equal(_max3x3(image), ndimage.grey_dilation(image, size=3))
        for m in (mask, np.zeros(shape, bool)):
            got, ref = _nonzero(m), np.nonzero(m)
            assert np.array_equal(got[0], ref[0]) and np.array_equal(got[1], ref[1])


def _reference_voxels(points, size):
    keys = np.floor((points - points.min(axis=0)) / size).astype(np.int64)
    dims = keys.max(axis=0) + 1
    flat = (keys[:, 0] * dims[1] + keys[:, 1]) * dims[2] + keys[:, 2]
    _, inverse, counts = np.unique(flat, return_inverse=True, return_counts=True)
    cent = np.column_stack(
        [
            np.bincount(inverse, weights=points[:, d], minlength=len(counts)) / counts
            for d in range(3)
        ]
    )
    return cent, inverse


def test_voxel_centroids_equal_the_reference():
    from posedrift.points._downsample import _voxel_centroids

    rng = np.random.default_rng(2)
    depth, _ = _person_depth()
    clouds = [backproject(depth, K)[0], rng.uniform(size=(3000, 3)) * 50, rng.normal(size=(1, 3))]
    for pts in clouds:
        for size in (0.005, 0.03, 0.2):  # the sparse grids take the np.unique path
            ref = _reference_voxels(pts, size)
            for compiled in (True, False):  # the kernel (where built) and its twin
                got = _voxel_centroids(pts, size, compiled=compiled)
                assert np.array_equal(got[0], ref[0]) and np.array_equal(got[1], ref[1])
