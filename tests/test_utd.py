"""The UTD-MHAD loader on the real data: the reference must land on the person."""

import shutil

import numpy as np
import pytest
from scipy import ndimage

from posedrift.camera import backproject, project
from posedrift.evaluation import find_utd_sequences, kinect20_to_joints, load_utd_sequence
from posedrift.skeleton import JOINT_INDEX

pytestmark = pytest.mark.data


@pytest.fixture(scope="module")
def swipe(utd_dir):
    found, _ = find_utd_sequences(utd_dir)
    by_name = {name: (d, s) for name, d, s in found}
    return load_utd_sequence(*by_name["a1_s1_t1"])


def test_find_pairs_all_sequences(utd_dir):
    found, skipped = find_utd_sequences(utd_dir)
    assert len(found) == 216 and skipped == []
    assert found[0][0] == "a1_s1_t1"
    assert found[1][0] == "a1_s1_t2"


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
