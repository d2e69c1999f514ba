"""The UTD-MHAD loader: on the real data the reference must land on the person; crafted
files check that bad files are named and odd names reported."""

import shutil

import numpy as np
import pytest
from scipy import ndimage

from posedrift.camera import backproject, project
from posedrift.evaluation import find_utd_sequences, kinect20_to_joints, load_utd_sequence
from posedrift.skeleton import JOINT_INDEX


@pytest.fixture(scope="module")
def swipe(utd_dir):
    found, _ = find_utd_sequences(utd_dir)
    by_name = {name: (d, s) for name, d, s in found}
    return load_utd_sequence(*by_name["a1_s1_t1"])


@pytest.mark.data
def test_find_pairs_all_sequences(utd_dir):
    found, skipped = find_utd_sequences(utd_dir)
    assert len(found) == 216 and skipped == []
    assert found[0][0] == "a1_s1_t1"
    assert found[1][0] == "a1_s1_t2"


@pytest.mark.data
def test_reference_projects_onto_the_silhouette(swipe):
    k = swipe.frames[0].intrinsics
    inside = []
    for frame, joints in zip(swipe.frames, swipe.reference.joints, strict=True):
        mask = ndimage.binary_dilation(frame.depth > 0, iterations=2)
        uv = np.rint(project(joints, k)).astype(int)
        ok = (uv[:, 0] >= 0) & (uv[:, 0] < k.width) & (uv[:, 1] >= 0) & (uv[:, 1] < k.height)
        hit = np.zeros(len(uv), bool)
        hit[ok] = mask[uv[ok, 1], uv[ok, 0]]
        inside.append(hit.mean())
    assert np.mean(inside) > 0.95
    # depth of the joints close to the surface depth (the skeleton sits inside the body)
    pts, _ = backproject(swipe.frames[0].depth, k)
    torso = swipe.reference.joints[0, JOINT_INDEX["torso"]]
    assert 0.0 < torso[2] - np.median(pts[:, 2]) < 0.25


@pytest.mark.data
def test_unmirrored_geometry_puts_the_right_arm_on_the_image_left(swipe):
    # a1 is a right-arm swipe; after un-mirroring, a person facing the camera has
    # their right side at smaller X (image left) and the moving wrist is the right one.
    j = swipe.reference.joints
    assert np.all(j[:, JOINT_INDEX["right_shoulder"], 0] < j[:, JOINT_INDEX["left_shoulder"], 0])
    right = np.ptp(j[:, JOINT_INDEX["right_hand"]], axis=0).max()
    left = np.ptp(j[:, JOINT_INDEX["left_hand"]], axis=0).max()
    assert right > 0.4 > 0.1 > left
    # camera frame: +Y down, so the head is above (smaller Y than) the feet
    assert np.all(j[:, JOINT_INDEX["head"], 1] < j[:, JOINT_INDEX["right_foot"], 1] - 1.0)
    assert swipe.reference.kind == "kinect" and swipe.reference.labels is None
    assert swipe.frames[0].intrinsics.cx == 159.0


@pytest.mark.data
def test_mirrored_option_is_the_exact_mirror(utd_dir, swipe):
    found, _ = find_utd_sequences(utd_dir)
    d, s = next((d, s) for n, d, s in found if n == "a1_s1_t1")
    raw = load_utd_sequence(d, s, unmirror=False)
    a, _ = backproject(swipe.frames[5].depth, swipe.frames[5].intrinsics)
    b, _ = backproject(raw.frames[5].depth, raw.frames[5].intrinsics)
    np.testing.assert_allclose(np.sort(a[:, 0]), np.sort(-b[:, 0]), atol=1e-6)
    np.testing.assert_allclose(raw.reference.joints[..., 0], -swipe.reference.joints[..., 0])


def test_torso_is_the_neck_pelvis_midpoint():
    skel = np.random.default_rng(0).normal(size=(3, 20, 3))
    j = kinect20_to_joints(skel)
    pelvis = 0.5 * (j[:, JOINT_INDEX["right_hip"]] + j[:, JOINT_INDEX["left_hip"]])
    np.testing.assert_allclose(
        j[:, JOINT_INDEX["torso"]], 0.5 * (j[:, JOINT_INDEX["neck"]] + pelvis)
    )
    skel[1] = 0.0  # the SDK's "not tracked"
    assert np.isnan(kinect20_to_joints(skel)[1]).all()
    with pytest.raises(ValueError, match="shape \\(T, 20, 3\\)"):
        kinect20_to_joints(np.zeros((3, 15, 3)))


@pytest.mark.data
def test_bad_files_are_named(tmp_path, utd_dir):
    (tmp_path / "Depth").mkdir()
    (tmp_path / "Skeleton").mkdir()
    shutil.copy(utd_dir / "Depth" / "a1_s1_t1_depth.mat", tmp_path / "Depth")
    shutil.copy(utd_dir / "Depth" / "a2_s1_t1_depth.mat", tmp_path / "Depth")
    shutil.copy(utd_dir / "Skeleton" / "a1_s1_t1_skeleton.mat", tmp_path / "Skeleton")
    found, skipped = find_utd_sequences(tmp_path)
    assert [f[0] for f in found] == ["a1_s1_t1"]
    assert skipped[0][0] == "a2_s1_t1" and "no skeleton file" in skipped[0][1]
    from scipy.io import loadmat, savemat

    skel = loadmat(str(tmp_path / "Skeleton" / "a1_s1_t1_skeleton.mat"))["d_skel"]
    short = tmp_path / "short_skeleton.mat"
    savemat(str(short), {"d_skel": skel[:, :, :10]})
    with pytest.raises(ValueError, match="has 10 frames, fewer than the"):
        load_utd_sequence(found[0][1], short)
    with pytest.raises(ValueError, match="does not exist"):
        load_utd_sequence(tmp_path / "nothing_depth.mat", short)
    with pytest.raises(ValueError, match="no 'a\\*_s\\*_t\\*_depth.mat' files"):
        find_utd_sequences(tmp_path / "Skeleton")


# --- crafted files (no data needed): empty, untracked, odd names, repeats, limit ----------------


def _standing(frames):
    """A (20, 3, T) Kinect skeleton about 3 m in front of the sensor (metres)."""
    rng = np.random.default_rng(1)
    joints = rng.normal(scale=0.3, size=(20, 3)) + [0.0, 0.0, 3.0]
    return np.repeat(joints[:, :, None], frames, axis=2)


def _write_utd(root, name, *, frames=3, depth=None, skel=None, skel_name=None):
    """Write ``Depth/{name}_depth.mat`` and ``Skeleton/{skel_name}_skeleton.mat`` (skel=False:
    no skeleton file); returns (depth path, skeleton path)."""
    from scipy.io import savemat

    (root / "Depth").mkdir(exist_ok=True)
    (root / "Skeleton").mkdir(exist_ok=True)
    if depth is None:
        depth = np.zeros((240, 320, frames), np.uint16)
        depth[60:200, 140:180] = 3000
    depth_path = root / "Depth" / f"{name}_depth.mat"
    savemat(str(depth_path), {"d_depth": depth}, do_compression=True)
    skel_path = root / "Skeleton" / f"{skel_name or name}_skeleton.mat"
    if skel is not False:
        savemat(str(skel_path), {"d_skel": _standing(frames) if skel is None else skel})
    return depth_path, skel_path


def test_empty_files_are_rejected_naming_the_file(tmp_path):
    good_depth, good_skel = _write_utd(tmp_path, "a1_s1_t1")
    assert len(load_utd_sequence(good_depth, good_skel).frames) == 3
    empty_depth, _ = _write_utd(tmp_path, "a3_s1_t1", depth=np.zeros((240, 320, 0), np.uint16))
    with pytest.raises(ValueError, match=r"a3_s1_t1_depth.mat' holds no frames .*\(240, 320, 0\)"):
        load_utd_sequence(empty_depth, good_skel)
    _, empty_skel = _write_utd(tmp_path, "a4_s1_t1", skel=np.zeros((20, 3, 0)))
    with pytest.raises(ValueError, match=r"a4_s1_t1_skeleton.mat' holds no frames"):
        load_utd_sequence(good_depth, empty_skel)


@pytest.mark.parametrize("fill", [0.0, np.nan, np.inf])
def test_reference_without_a_tracked_frame_is_rejected(tmp_path, fill):
    depth, skel = _write_utd(tmp_path, "a4_s1_t1", skel=np.full((20, 3, 3), fill))
    with pytest.raises(ValueError, match=r"a4_s1_t1_skeleton.mat' has no usable frame"):
        load_utd_sequence(depth, skel)
    # One tracked frame is enough: the untracked ones become NaN.
    partly = _standing(3)
    partly[:, :, [0, 2]] = fill
    depth, skel = _write_utd(tmp_path, "a5_s1_t1", skel=partly)
    joints = load_utd_sequence(depth, skel).reference.joints
    assert np.isnan(joints[[0, 2]]).all() and np.isfinite(joints[1]).all()


def test_names_in_any_case_and_odd_names_reported(tmp_path):
    upper, _ = _write_utd(tmp_path, "A1_S1_T1", skel_name="a1_s1_t1")  # paired in any case
    copy, copy_skel = _write_utd(tmp_path, "a5_s1_t1 (copy)")
    _write_utd(tmp_path, "a2_s1_t1")
    (tmp_path / "Skeleton" / "a2_s1_t1_skeleton.mat").rename(
        tmp_path / "Skeleton" / "A2_S1_T1_SKELETON.MAT"
    )
    _, orphan = _write_utd(tmp_path, "a9_s1_t1")
    (tmp_path / "Depth" / "a9_s1_t1_depth.mat").unlink()  # a skeleton without depth
    junk = tmp_path / "Skeleton" / "junk_skeleton.mat"
    junk.write_bytes(b"")
    reported = []
    found, skipped = find_utd_sequences(tmp_path, on_ignored=lambda *a: reported.append(a))
    assert [(n, d.name, s.name) for n, d, s in found] == [
        ("A1_S1_T1", "A1_S1_T1_depth.mat", "a1_s1_t1_skeleton.mat"),
        ("a2_s1_t1", "a2_s1_t1_depth.mat", "A2_S1_T1_SKELETON.MAT"),
    ]
    assert skipped == []
    # Each odd file named once (the copy's skeleton goes with its depth file).
    assert [item for item, _ in reported] == [str(copy), str(orphan), str(junk)]
    assert "does not follow a<action>_s<subject>_t<trial>_depth.mat" in reported[0][1]
    assert "'a5_s1_t1 (copy)'" in reported[0][1] and "no depth file" in reported[1][1]
    # Without a callback: one RuntimeWarning per file.
    with pytest.warns(RuntimeWarning) as caught:
        find_utd_sequences(tmp_path)
    assert [str(w.message) for w in caught] == [f"{item}: {why}" for item, why in reported]
    # Asked for by name: the odd file is a sequence; case-insensitive; repeats count once.
    reported.clear()
    found, skipped = find_utd_sequences(
        tmp_path,
        names=["a5_s1_t1 (copy)", "a1_s1_t1", "A1_S1_T1", "a5_s1_t1 (copy)", "a7_s1_t1"],
        on_ignored=lambda *a: reported.append(a),
    )
    assert [(n, d, s) for n, d, s in found] == [
        ("a5_s1_t1 (copy)", copy, copy_skel),
        ("A1_S1_T1", upper, tmp_path / "Skeleton" / "a1_s1_t1_skeleton.mat"),
    ]
    assert skipped == [("a7_s1_t1", "no such sequence in the folder")]
    assert reported == [
        ("A1_S1_T1", "the same file as 'a1_s1_t1' (A1_S1_T1_depth.mat): taken once"),
        ("a5_s1_t1 (copy)", "named more than once: taken once"),
    ]


def test_limit_counts_sequences_in_order_paired_or_not(tmp_path):
    for name in ("a1_s1_t1", "a3_s1_t1"):
        _write_utd(tmp_path, name)
    _write_utd(tmp_path, "a2_s1_t1", skel=False)
    found, skipped = find_utd_sequences(tmp_path, limit=1)
    assert [f[0] for f in found] == ["a1_s1_t1"] and skipped == []
    found, skipped = find_utd_sequences(tmp_path, limit=2)
    assert [f[0] for f in found] == ["a1_s1_t1"]
    assert skipped == [
        ("a2_s1_t1", f"no skeleton file {str(tmp_path / 'Skeleton' / 'a2_s1_t1_skeleton.mat')!r}")
    ]
    found, skipped = find_utd_sequences(tmp_path, names=["a3_s1_t1", "a2_s1_t1"], limit=1)
    assert [f[0] for f in found] == ["a3_s1_t1"] and skipped == []
    with pytest.raises(ValueError, match="'limit' argument must be at least 1. Got 0"):
        find_utd_sequences(tmp_path, limit=0)


def test_floating_point_depth_is_metres(tmp_path):
    millimetres = np.zeros((240, 320, 2), np.uint16)
    millimetres[60:200, 140:180] = 2873
    mm_depth, skel = _write_utd(tmp_path, "a1_s1_t1", frames=2, depth=millimetres)
    m_depth, _ = _write_utd(tmp_path, "a2_s1_t1", frames=2, depth=millimetres / 1000.0)
    a = load_utd_sequence(mm_depth, skel).frames[0].depth
    b = load_utd_sequence(m_depth, skel).frames[0].depth
    np.testing.assert_allclose(b, a, atol=1e-6)
    assert abs(float(a.max()) - 2.873) < 1e-6  # metres


@pytest.mark.data
def test_real_recordings_read_a_level_camera_and_a_seated_start_gives_no_tilt(utd_dir):
    """The world's up on real Kinect recordings: a person standing at the first frame reads
    the level camera within its 5-degree dead zone (the tracker's level path), and one who
    begins seated (a24, sit to stand) gives no estimate at all."""
    from posedrift.tracking import PoseTracker
    from posedrift.tracking._init import CAMERA_UP

    found, _ = find_utd_sequences(utd_dir, names=["a1_s2_t1", "a4_s1_t1", "a24_s1_t1"])
    tilts = {}
    for name, depth, skeleton in found:
        seq = load_utd_sequence(depth, skeleton, name=name)
        tracker = PoseTracker(seq.frames[0].intrinsics, rng=0)
        for frame in seq.frames[:2]:
            tracker.process(frame)
        tilts[name] = tracker._camera_tilt()
        if name == "a24_s1_t1":
            np.testing.assert_array_equal(tracker.calibration.up, CAMERA_UP)
        else:  # measured: 3.3 and 2.3 degrees
            assert abs(tilts[name]) < 5.0 and tracker._level() is None
    assert len(tilts) == 3
