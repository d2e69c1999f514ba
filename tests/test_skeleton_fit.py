"""Mean-shift part modes and the skeleton fit with calibrated bone lengths."""

from __future__ import annotations

import numpy as np
import pytest

from posedrift.labelling import geodesic_graph
from posedrift.points import downsample
from posedrift.skeleton import ANGLE_NAMES, JOINT_INDEX, JOINT_PARENTS, joint_angles, part_modes
from posedrift.skeleton._fit import (
    _J,
    _LIMBS,
    _P,
    ELBOW_BOUNDARY_SHIFT,
    ELBOW_FULL_SHIFT_BEND,
    KNEE_BOUNDARY_SHIFT,
    LIMB_DIRECTION_WEIGHTS,
    N_PARTS,
    PART_RADII,
    PELVIS_TILT_LIMIT,
    PREDICTED_SIGN_WEIGHT,
    RING_BACK_RADII,
    RING_JOINTS,
    SEGMENT_RATIOS,
    SkeletonFit,
    _anchor_shoulders,
    _brace_pelvis,
    _place_limbs,
    bone_anchors,
    fit_skeleton,
    image_exits,
    part_axes,
    part_boundaries,
    prior_bone_lengths,
    ring_joints,
    shoulder_offset_of,
)

J = JOINT_INDEX
J_ANGLE = {name: i for i, name in enumerate(ANGLE_NAMES)}


def test_part_modes_find_the_dense_cluster():
    rng = np.random.default_rng(0)
    dense = rng.normal(scale=0.01, size=(200, 3)) + [0.0, 0.0, 2.0]
    sparse = rng.uniform(-0.3, 0.3, size=(40, 3)) + [0.5, 0.0, 2.0]
    pts = np.vstack([dense, sparse])
    labels = np.zeros(len(pts), dtype=int)
    labels[-5:] = 3
    modes, counts = part_modes(pts, labels, bandwidth=0.05, return_counts=True)
    assert np.linalg.norm(modes[0] - [0.0, 0.0, 2.0]) < 0.01  # the mean would be 7 cm off
    assert np.isnan(modes[1]).all() and counts[1] == 0
    assert counts[0] == len(pts) - 5 and counts[3] == 5


def test_part_modes_weights_and_errors():
    pts = np.array([[0.0, 0, 0], [1.0, 0, 0]])
    modes = part_modes(pts, np.array([0, 0]), bandwidth=10.0, weights=np.array([3.0, 1.0]))
    assert abs(modes[0, 0] - 0.25) < 0.01
    with pytest.raises(ValueError, match="'labels' argument of part_modes"):
        part_modes(pts, np.array([0]))
    with pytest.raises(ValueError, match="'bandwidth' parameter of part_modes"):
        part_modes(pts, np.array([0, 0]), bandwidth=0.0)
    with pytest.raises(ValueError, match="'weights' argument of part_modes"):
        part_modes(pts, np.array([0, 0]), weights=np.array([-1.0, 1.0]))


@pytest.fixture(scope="module")
def rendered():
    """Rendered frames of the built-in motion (body model, ground-truth labels)."""
    from posedrift.synthetic import build_sequence, procedural_motion

    return build_sequence(procedural_motion(), n_frames=150, rng=0)


def _frame_points(seq, i, n=400, *, return_voxel_size=False):
    from posedrift.camera import backproject, project
    from posedrift.points import segment_person
    from posedrift.tracking._init import label_template_points

    frame = seq.frames[i]
    full, pix = backproject(frame.depth, frame.intrinsics, segment_person(frame))
    points, voxel = downsample(full, n, rng=0, return_voxel_size=True)
    truth = seq.reference.labels[i].astype(int) - 1
    labels = label_template_points(points, full, truth[pix[:, 0], pix[:, 1]])
    assert np.isfinite(project(points, frame.intrinsics)).all()
    return (points, labels, voxel) if return_voxel_size else (points, labels)


def _true_bones(joints):
    bones = np.zeros(15)
    for i, p in enumerate(JOINT_PARENTS):
        if p >= 0:
            bones[i] = np.linalg.norm(joints[i] - joints[p])
    return bones


def test_fit_skeleton_from_true_labels_matches_ground_truth(rendered):
    errors, joint_err = [], []
    bones = _true_bones(rendered.reference.joints[0])
    for i in range(0, 150, 10):
        points, labels = _frame_points(rendered, i)
        graph = geodesic_graph(points)
        fit = fit_skeleton(points, labels, bone_lengths=bones, edges=(graph.rows, graph.cols))
        assert fit.measured.mean() > 0.9
        assert np.all((fit.confidence >= 0) & (fit.confidence <= 1))
        truth = rendered.reference.joints[i]
        errors.append(np.abs(joint_angles(fit.joints) - rendered.reference.angles[i]))
        joint_err.append(np.linalg.norm(fit.joints - truth, axis=1))
        # Limb bones have exactly their calibrated lengths.
        for child in ("right_elbow", "left_hand", "right_knee", "left_foot"):
            parent = JOINT_PARENTS[J[child]]
            length = np.linalg.norm(fit.joints[J[child]] - fit.joints[parent])
            assert abs(length - bones[J[child]]) < 1e-9 or child == "right_elbow"
    errors, joint_err = np.array(errors), np.array(joint_err)
    assert np.mean(errors) < 6.0  # degrees, over the eight angles
    assert np.percentile(errors, 90) < 15.0
    assert np.mean(joint_err) < 0.05  # metres
    assert np.mean(joint_err < 0.10) > 0.95


@pytest.fixture(scope="module")
def rendered_from_behind():
    """The built-in motion with the person's back to the camera."""
    from posedrift.synthetic import build_sequence, procedural_motion

    return build_sequence(procedural_motion(), n_frames=150, rng=0, facing=180.0)


def test_fit_skeleton_seen_from_behind_needs_the_back_radii(rendered_from_behind):
    """From behind, the hip and knee boundaries lie elsewhere on the body: the front's
    push-back radii put the hips 9 cm too deep and bend the legs by some 18 degrees."""
    seq = rendered_from_behind
    bones = _true_bones(seq.reference.joints[0])
    hips = [J["right_hip"], J["left_hip"]]
    results = {}
    for facing in (None, 180.0):
        errors, hip_err = [], []
        for i in range(0, 150, 10):
            points, labels = _frame_points(seq, i)
            graph = geodesic_graph(points)
            fit = fit_skeleton(
                points, labels, bone_lengths=bones, edges=(graph.rows, graph.cols), facing=facing
            )
            errors.append(np.abs(joint_angles(fit.joints) - seq.reference.angles[i]))
            hip_err.append(np.linalg.norm(fit.joints[hips] - seq.reference.joints[i][hips], axis=1))
        results[facing] = np.array(errors), np.mean(hip_err)
    errors, hip_err = results[180.0]
    assert np.mean(errors) < 6.0 and np.mean(errors[:, 4:]) < 8.0  # degrees; legs last
    assert hip_err < 0.05  # metres
    front_errors, front_hip_err = results[None]
    assert np.mean(front_errors[:, 4:]) > 12.0 and front_hip_err > 0.07


def test_ring_joints_blend_the_back_radii_by_the_facing():
    centres = np.full((N_PARTS, N_PARTS, 3), np.nan)
    counts = np.zeros((N_PARTS, N_PARTS), dtype=int)
    a, b = _P["head"], _P["upper_torso"]
    centres[a, b] = centres[b, a] = [0.0, -0.5, 2.5]
    counts[a, b] = counts[b, a] = 4

    def distance(facing):
        neck = ring_joints(centres, counts, height=1.75, facing=facing)["neck"][0]
        return np.linalg.norm(neck - centres[a, b])

    front, back = RING_JOINTS["neck"][2], RING_BACK_RADII["neck"]
    # None and NaN (a facing that cannot be measured) mean seen from the front.
    assert distance(None) == distance(0.0) == distance(float("nan"))
    # Up to side-on the front radii; beyond, -cos(facing) of the way to the back ones.
    w = np.sqrt(0.5)
    np.testing.assert_allclose(
        [distance(f) for f in (0.0, 60.0, 90.0, -90.0, 135.0, 180.0, -180.0)],
        [front, front, front, front, (1 - w) * front + w * back, back, back],
        atol=1e-12,
    )
    assert set(RING_BACK_RADII) == set(RING_JOINTS)


def test_fit_skeleton_falls_back_on_the_prediction(rendered):
    points, labels = _frame_points(rendered, 0)
    bones = _true_bones(rendered.reference.joints[0])
    truth = rendered.reference.joints[0]
    keep = ~np.isin(labels, [5, 7])  # the right forearm and hand are not seen
    sub = geodesic_graph(points[keep])
    fit = fit_skeleton(
        points[keep], labels[keep], bone_lengths=bones, edges=(sub.rows, sub.cols), prediction=truth
    )
    assert np.isfinite(fit.joints).all()
    assert not fit.measured[J["right_hand"]]
    assert fit.confidence[J["right_hand"]] < 0.5
    assert np.linalg.norm(fit.joints[J["right_hand"]] - truth[J["right_hand"]]) < 0.08
    # Without a prediction the unsupported joints are unknown (NaN), not invented.
    bare = fit_skeleton(points[keep], labels[keep], bone_lengths=bones, edges=(sub.rows, sub.cols))
    assert np.isnan(bare.joints[J["right_hand"]]).all()
    assert bare.confidence[J["right_hand"]] == 0.0


def _posed_t_pose(height=1.75):
    """A T-pose turned 30 degrees about the vertical and 2.5 m in front of the camera."""
    from scipy.spatial.transform import Rotation

    from posedrift.skeleton import t_pose_joints

    turn = Rotation.from_euler("y", 30, degrees=True).as_matrix()
    return t_pose_joints(height) @ turn.T + [0.1, -0.2, 2.5]


def test_anchored_shoulders_leave_a_t_pose_alone():
    joints = _posed_t_pose()
    bones = _true_bones(joints)
    out = joints.copy()
    _anchor_shoulders(out, bone_lengths=bones, height=1.75, weight=1.0)
    np.testing.assert_allclose(out, joints, atol=1e-12)


@pytest.mark.parametrize("weight", [0.3, 1.0])
def test_anchored_shoulders_move_towards_the_trunk_and_carry_the_arm(weight):
    joints = _posed_t_pose()
    bones = _true_bones(joints)
    arm = [J[f"left_{j}"] for j in ("shoulder", "elbow", "hand")]
    moved = joints.copy()
    moved[arm] += [0.0, 0.06, -0.04]  # the arm's shoulder placed 7 cm off the trunk
    out = moved.copy()
    _anchor_shoulders(out, bone_lengths=bones, height=1.75, weight=weight)
    shoulder, elbow, hand = arm
    np.testing.assert_allclose(
        out[shoulder], (1 - weight) * moved[shoulder] + weight * joints[shoulder], atol=1e-12
    )
    # The upper arm keeps its length and turns to the elbow; the forearm is carried along.
    assert abs(np.linalg.norm(out[elbow] - out[shoulder]) - bones[elbow]) < 1e-12
    np.testing.assert_allclose(out[hand] - out[elbow], moved[hand] - moved[elbow], atol=1e-12)
    # The other arm, already on the trunk, and every other joint stay put.
    others = np.setdiff1d(np.arange(15), arm)
    np.testing.assert_allclose(out[others], moved[others], atol=1e-12)


def test_shoulder_offset_of_a_t_pose_is_its_geometry():
    across, below = shoulder_offset_of(_posed_t_pose(1.6))
    assert abs(across - 0.5 * SEGMENT_RATIOS["shoulder_width"] * 1.6) < 1e-12
    assert abs(below - SEGMENT_RATIOS["neck_above_shoulders"] * 1.6) < 1e-12


def test_anchored_shoulders_go_to_a_given_offset():
    joints = _posed_t_pose()
    bones = _true_bones(joints)
    out = joints.copy()
    # The offset measured on the same skeleton: nothing moves.
    _anchor_shoulders(
        out, bone_lengths=bones, height=1.75, weight=1.0, offset=shoulder_offset_of(joints)
    )
    np.testing.assert_allclose(out, joints, atol=1e-12)
    # Another person's: 4 cm lower and 2 cm narrower, and so they end.
    wanted = shoulder_offset_of(joints) + [-0.02, 0.04]
    _anchor_shoulders(out, bone_lengths=bones, height=1.75, weight=1.0, offset=wanted)
    np.testing.assert_allclose(shoulder_offset_of(out), wanted, atol=1e-12)


def test_anchored_shoulders_need_the_trunk():
    joints = _posed_t_pose()
    joints[J["right_hip"]] = np.nan
    out = joints.copy()
    _anchor_shoulders(out, bone_lengths=_true_bones(_posed_t_pose()), height=1.75, weight=1.0)
    np.testing.assert_array_equal(out, joints)


def _hip_line(joints):
    """Width (metres) and tilt from square to the trunk (degrees) of the hips' line."""
    across = joints[J["right_hip"]] - joints[J["left_hip"]]
    centre = 0.5 * (joints[J["right_hip"]] + joints[J["left_hip"]])
    up = joints[J["neck"]] - centre
    width = np.linalg.norm(across)
    return width, np.degrees(np.arcsin(abs(across @ up) / (width * np.linalg.norm(up))))


def test_braced_pelvis_leaves_a_t_pose_of_its_width_alone():
    joints = _posed_t_pose()
    out = joints.copy()
    width = _hip_line(joints)[0]
    _brace_pelvis(out, bone_lengths=_true_bones(joints), width=width, max_tilt=PELVIS_TILT_LIMIT)
    np.testing.assert_allclose(out, joints, atol=1e-12)


def _trunk_frame(joints):
    """The trunk's up and the unit from the left hip to the right one."""
    right, left = joints[J["right_hip"]], joints[J["left_hip"]]
    up = joints[J["neck"]] - 0.5 * (right + left)
    return up / np.linalg.norm(up), (right - left) / np.linalg.norm(right - left)


def _on_thigh(joints, bones, side, target):
    """``joints`` with the ``side`` hip moved towards ``target`` on its thigh's sphere."""
    out = joints.copy()
    hip, knee = J[f"{side}_hip"], J[f"{side}_knee"]
    towards = target - out[knee]
    out[hip] = out[knee] + bones[knee] * towards / np.linalg.norm(towards)
    return out


def _worst_error(joints, truth, names):
    """The largest error in degrees of the angles ``names``."""
    errors = np.abs(joint_angles(joints) - joint_angles(truth))
    return max(errors[J_ANGLE[name]] for name in names)


HIPS, KNEES = ("left_hip", "right_hip"), ("left_knee", "right_knee")


def test_braced_pelvis_brings_a_hidden_hip_back():
    # A hip the thigh placed 5 cm in (a leg crossing in front of it).
    joints = _posed_t_pose()
    bones = _true_bones(joints)
    width = _hip_line(joints)[0]
    rightwards = _trunk_frame(joints)[1]
    moved = _on_thigh(joints, bones, "left", joints[J["left_hip"]] + 0.05 * rightwards)
    out = moved.copy()
    _brace_pelvis(out, bone_lengths=bones, width=width, max_tilt=PELVIS_TILT_LIMIT)
    assert abs(_hip_line(moved)[0] - width) > 0.045
    assert abs(_hip_line(out)[0] - width) < 0.001  # metres
    # The knees and feet, measured, stay; the thighs keep their length.
    for side in ("right", "left"):
        hip, knee = J[f"{side}_hip"], J[f"{side}_knee"]
        assert abs(np.linalg.norm(out[knee] - out[hip]) - bones[knee]) < 1e-12
    others = np.setdiff1d(np.arange(15), [J["right_hip"], J["left_hip"]])
    np.testing.assert_array_equal(out[others], moved[others])
    # The error is shared between the sides: the worst hip angle from 9.3 to 6.0 degrees,
    # the worst knee from 6.7 to 3.3.
    assert _worst_error(out, joints, HIPS) < _worst_error(moved, joints, HIPS) - 3.0
    assert _worst_error(out, joints, KNEES) < _worst_error(moved, joints, KNEES) - 3.0


def _seated(joints, bones):
    """``joints`` with the thighs forward and the shanks down, as on a chair."""
    out = joints.copy()
    up, rightwards = _trunk_frame(joints)
    for side in ("right", "left"):
        hip, knee, foot = (J[f"{side}_{name}"] for name in ("hip", "knee", "foot"))
        out[knee] = out[hip] + bones[knee] * np.cross(rightwards, up)
        out[foot] = out[knee] - bones[foot] * up
    return out


def test_braced_pelvis_turns_a_tilted_hip_line_back_to_the_limit():
    # Seated: a hip the thigh placed 6 cm low tilts the line 10 degrees.
    bones = _true_bones(_posed_t_pose())
    joints = _seated(_posed_t_pose(), bones)
    up = _trunk_frame(joints)[0]
    moved = _on_thigh(joints, bones, "left", joints[J["left_hip"]] - 0.06 * up)
    out = moved.copy()
    _brace_pelvis(out, bone_lengths=bones, width=_hip_line(joints)[0], max_tilt=PELVIS_TILT_LIMIT)
    assert _hip_line(moved)[1] > PELVIS_TILT_LIMIT + 3
    assert abs(_hip_line(out)[1] - PELVIS_TILT_LIMIT) < 0.1  # degrees
    # The worst hip angle from 7.8 to 6.2 degrees, the worst knee from 8.0 to 6.3.
    assert _worst_error(out, joints, HIPS) < _worst_error(moved, joints, HIPS) - 1.5
    assert _worst_error(out, joints, KNEES) < _worst_error(moved, joints, KNEES) - 1.5


def test_braced_pelvis_keeps_a_tilt_within_the_limit():
    # Seated, the hips 4 cm narrow and tilted 2 degrees: the width restored, the tilt kept.
    bones = _true_bones(_posed_t_pose())
    joints = _seated(_posed_t_pose(), bones)
    up, rightwards = _trunk_frame(joints)
    moved = _on_thigh(joints, bones, "left", joints[J["left_hip"]] + 0.02 * rightwards)
    moved = _on_thigh(moved, bones, "right", joints[J["right_hip"]] - 0.02 * rightwards)
    moved = _on_thigh(moved, bones, "left", moved[J["left_hip"]] - 0.01 * up)
    assert 1.0 < _hip_line(moved)[1] < 3.0
    out = moved.copy()
    _brace_pelvis(out, bone_lengths=bones, width=_hip_line(joints)[0], max_tilt=PELVIS_TILT_LIMIT)
    assert abs(_hip_line(out)[0] - _hip_line(joints)[0]) < 0.001
    assert abs(_hip_line(out)[1] - _hip_line(moved)[1]) < 0.5


def test_braced_pelvis_needs_the_trunk_and_a_width():
    joints = _posed_t_pose()
    joints[J["neck"]] = np.nan
    out = joints.copy()
    bones = _true_bones(_posed_t_pose())
    _brace_pelvis(out, bone_lengths=bones, width=0.3, max_tilt=PELVIS_TILT_LIMIT)
    np.testing.assert_array_equal(out, joints)
    joints = _posed_t_pose()
    out = joints.copy()
    _brace_pelvis(out, bone_lengths=bones, width=np.nan, max_tilt=PELVIS_TILT_LIMIT)
    np.testing.assert_array_equal(out, joints)


def test_fit_skeleton_reports_the_placed_width_and_braces_to_the_given_one(rendered):
    points, labels = _frame_points(rendered, 60)
    graph = geodesic_graph(points)
    bones = _true_bones(rendered.reference.joints[0])
    kwargs = {"bone_lengths": bones, "edges": (graph.rows, graph.cols)}
    free = fit_skeleton(points, labels, **kwargs)
    assert abs(free.pelvis_width - _hip_line(free.joints)[0]) < 1e-12
    braced = fit_skeleton(points, labels, pelvis_width=free.pelvis_width + 0.05, **kwargs)
    assert abs(_hip_line(braced.joints)[0] - (free.pelvis_width + 0.05)) < 0.003
    assert braced.pelvis_width == free.pelvis_width  # the width placed, before bracing


def test_prior_bone_lengths_follow_the_ratios():
    bones = prior_bone_lengths(1.75)
    assert abs(bones[J["right_elbow"]] - 0.186 * 1.75) < 1e-9
    assert abs(bones[J["left_foot"]] - 0.246 * 1.75) < 1e-9
    assert bones[J["torso"]] == 0.0


def test_image_exits_are_where_the_parts_touch_the_border():
    from posedrift.camera import Intrinsics

    k = Intrinsics(fx=285.6, fy=285.6, cx=159.5, cy=119.5, width=320, height=240)

    def at(u, v, z=2.0):  # the point that projects to pixel (u, v)
        return [(u - k.cx) * z / k.fx, (v - k.cy) * z / k.fy, z]

    points = np.array(
        [at(160, 120), at(0, 100), at(200, 239), at(210, 239), at(3, 50), at(319, 10), at(5, 5)]
    )
    labels = np.array([1, 11, 12, 12, 5, -1, 20])  # -1 and 20: not parts, ignored
    exits = image_exits(points, labels, k)
    assert exits.shape == (N_PARTS, 3)
    assert np.flatnonzero(np.isfinite(exits[:, 0])).tolist() == [11, 12]
    assert np.isnan(exits[[0, 1, 5]]).all()
    np.testing.assert_allclose(exits[11], points[1], atol=1e-12)
    np.testing.assert_allclose(exits[12], points[2:4].mean(axis=0), atol=1e-12)  # their centroid
    # A voxel of 2.5 cm is 3.6 pixels at 2 m: the point 3 pixels in is at the edge too.
    wide = image_exits(points, labels, k, voxel_size=0.025)
    assert np.flatnonzero(np.isfinite(wide[:, 0])).tolist() == [5, 11, 12]
    assert np.isnan(image_exits(points[:0], labels[:0], k)).all()


@pytest.fixture(scope="module")
def rendered_near():
    """The built-in motion 1.6 m from the camera: the shanks are cut off by the lower edge."""
    from posedrift.synthetic import build_sequence, procedural_motion

    return build_sequence(procedural_motion(), n_frames=150, rng=0, distance=1.6)


def test_cut_off_shanks_follow_the_visible_surface(rendered_near):
    bones = _true_bones(rendered_near.reference.joints[0])
    knees = [J_ANGLE["left_knee"], J_ANGLE["right_knee"]]
    before, after = [], []
    for i in range(0, 150, 15):
        points, labels, voxel = _frame_points(rendered_near, i, return_voxel_size=True)
        graph = geodesic_graph(points)
        options = {"bone_lengths": bones, "edges": (graph.rows, graph.cols)}
        k = rendered_near.frames[i].intrinsics
        exits = image_exits(points, labels, k, voxel_size=voxel)
        assert np.isfinite(exits[[_P["right_shank"], _P["left_shank"]]]).all()
        assert np.isnan(exits[_P["upper_torso"]]).all()
        # The shanks leave the image at its lower edge.
        assert (exits[[_P["right_shank"], _P["left_shank"]], 1] > 0.5).all()
        plain = fit_skeleton(points, labels, **options)
        fit = fit_skeleton(points, labels, exits=exits, **options)
        truth = rendered_near.reference.angles[i]
        before.append(np.abs(joint_angles(plain.joints) - truth)[knees])
        after.append(np.abs(joint_angles(fit.joints) - truth)[knees])
        # Nothing cut: the fit is the one without cut parts, to the last bit.
        same = fit_skeleton(points, labels, exits=np.full((N_PARTS, 3), np.nan), **options)
        _assert_same(same, plain)
    # The straight knees read about 18 degrees bent from the pushed-back stub, about 9
    # along the surface towards where the shank leaves the image.
    assert np.mean(before) > 15.0
    assert np.mean(after) < 11.0
    assert np.mean(after) < np.mean(before) - 5.0


# ---------------------------------------------------------------------------------------------
# The fast skeleton fit against the original implementation (kept verbatim below, docstrings
# dropped): bit-for-bit equal outputs on real and random inputs.


def _ref_part_boundaries(
    points: np.ndarray, labels: np.ndarray, rows: np.ndarray, cols: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    la, lb = labels[rows], labels[cols]
    ok = (la != lb) & (la >= 0) & (lb >= 0) & (la < N_PARTS) & (lb < N_PARTS)
    a, b = np.minimum(la[ok], lb[ok]), np.maximum(la[ok], lb[ok])
    code = a * N_PARTS + b
    mid = 0.5 * (points[rows[ok]] + points[cols[ok]])
    counts = np.bincount(code, minlength=N_PARTS * N_PARTS)
    centres = np.full((N_PARTS * N_PARTS, 3), np.nan)
    have = counts > 0
    for d in range(3):
        centres[have, d] = (
            np.bincount(code, weights=mid[:, d], minlength=N_PARTS * N_PARTS)[have] / counts[have]
        )
    centres = centres.reshape(N_PARTS, N_PARTS, 3)
    counts = counts.reshape(N_PARTS, N_PARTS)
    upper = np.triu_indices(N_PARTS, 1)
    centres[upper[1], upper[0]] = centres[upper]
    counts = counts + counts.T
    return centres, counts


def _ref_part_axes(
    points: np.ndarray, labels: np.ndarray, *, min_points: int = 5
) -> tuple[np.ndarray, np.ndarray]:
    axes = np.full((N_PARTS, 3), np.nan)
    elong = np.zeros(N_PARTS)
    ok = (labels >= 0) & (labels < N_PARTS)
    lab, p = labels[ok], points[ok]
    counts = np.bincount(lab, minlength=N_PARTS)
    means = np.zeros((N_PARTS, 3))
    for d in range(3):
        means[:, d] = np.bincount(lab, weights=p[:, d], minlength=N_PARTS) / np.maximum(counts, 1)
    c = p - means[lab]
    cov = np.zeros((N_PARTS, 3, 3))
    for i in range(3):
        for j in range(i, 3):
            cov[:, i, j] = np.bincount(lab, weights=c[:, i] * c[:, j], minlength=N_PARTS)
            cov[:, j, i] = cov[:, i, j]
    good = counts >= min_points
    if good.any():
        w, v = np.linalg.eigh(cov[good])
        axes[good] = v[:, :, 2]
        elong[good] = w[:, 2] / np.maximum(w[:, 1], 1e-12)
    return axes, elong


def _ref_unit(v: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(v)
    return v / n if n > 1e-12 else np.full(3, np.nan)


def _ref_push(p: np.ndarray, radius: float) -> np.ndarray:
    return p + radius * _ref_unit(p)


def _ref_ring_joints(
    centres: np.ndarray,
    counts: np.ndarray,
    *,
    height: float,
    min_edges: int = 2,
    elbow_shift: float = 0.0,
) -> dict[str, tuple[np.ndarray, float]]:
    scale = height / 1.75
    raw = {}
    for name, (pa, pb, radius) in RING_JOINTS.items():
        a, b = _P[pa], _P[pb]
        if counts[a, b] >= min_edges:
            raw[name] = (_ref_push(centres[a, b], radius * scale), min(1.0, counts[a, b] / 4.0))
    out = dict(raw)
    for side in ("right", "left"):
        elbow, shoulder = raw.get(f"{side}_elbow"), raw.get(f"{side}_shoulder")
        if elbow_shift and elbow is not None and shoulder is not None:
            down = _ref_unit(elbow[0] - shoulder[0])
            share = 1.0
            if f"{side}_hand" in raw:
                cos = np.clip(down @ _ref_unit(raw[f"{side}_hand"][0] - elbow[0]), -1, 1)
                bend = np.degrees(np.arccos(cos))
                share = min(1.0, bend / ELBOW_FULL_SHIFT_BEND) if np.isfinite(bend) else 1.0
            down = share * elbow_shift * scale * down
            if np.isfinite(down).all():
                out[f"{side}_elbow"] = (elbow[0] + down, elbow[1])
    for side, other in (("right", "left"), ("left", "right")):
        knee, hip = raw.get(f"{side}_knee"), raw.get(f"{side}_hip")
        if knee is not None and hip is not None:
            up = _ref_unit(hip[0] - knee[0])
            out[f"{side}_knee"] = (knee[0] + KNEE_BOUNDARY_SHIFT * scale * up, knee[1])
            lateral = np.zeros(3)
            if f"{other}_hip" in raw:
                lat = hip[0] - raw[f"{other}_hip"][0]
                lat = lat - (lat @ up) * up
                lateral = 0.025 * scale * _ref_unit(lat)
            if np.isfinite(lateral).all():
                out[f"{side}_hip"] = (hip[0] + 0.035 * scale * up + lateral, hip[1])
        elif hip is not None:
            del out[f"{side}_hip"]
    trunk_up = None
    if "neck" in raw and "right_hip" in out and "left_hip" in out:
        trunk_up = _ref_unit(raw["neck"][0] - 0.5 * (out["right_hip"][0] + out["left_hip"][0]))
    for side in ("right", "left"):
        name = f"{side}_shoulder"
        if name in out:
            if trunk_up is not None and np.isfinite(trunk_up).all():
                out[name] = (raw[name][0] + 0.045 * scale * trunk_up, raw[name][1])
            else:
                del out[name]
    return out


def _ref_fit_skeleton(
    points: np.ndarray,
    labels: np.ndarray,
    *,
    bone_lengths: np.ndarray,
    edges: tuple[np.ndarray, np.ndarray],
    modes: np.ndarray | None = None,
    prediction: np.ndarray | None = None,
    height: float | None = None,
    min_edges: int = 2,
    min_part_points: int = 4,
    min_elongation: float = 3.0,
    smoothing: float = 0.0,
) -> SkeletonFit:
    from posedrift.skeleton._meanshift import part_modes

    points = np.asarray(points, dtype=float)
    labels = np.asarray(labels).astype(np.int64)
    bone_lengths = np.asarray(bone_lengths, dtype=float)
    if height is None:
        height = float(bone_lengths[_J["right_foot"]] / SEGMENT_RATIOS["shank"])
    rows, cols = edges
    if modes is None:
        modes = part_modes(points, labels, bandwidth=0.06)
    counts = np.bincount(labels[(labels >= 0) & (labels < N_PARTS)], minlength=N_PARTS)
    pred = None if prediction is None else np.asarray(prediction, dtype=float)
    centres, ecounts = _ref_part_boundaries(points, labels, rows, cols)
    axes, elong = _ref_part_axes(points, labels, min_points=min_part_points)
    ring = _ref_ring_joints(
        centres, ecounts, height=height, min_edges=min_edges, elbow_shift=ELBOW_BOUNDARY_SHIFT
    )

    joints = np.full((15, 3), np.nan)
    conf = np.zeros(15)
    measured = np.zeros(15, dtype=bool)

    def blend(i: int, value: np.ndarray) -> np.ndarray:
        if smoothing > 0 and pred is not None and np.isfinite(pred[i]).all():
            return (1.0 - smoothing) * value + smoothing * pred[i]
        return value

    for name in ("neck", "right_elbow", "left_elbow", "right_knee", "left_knee"):
        i = _J[name]
        if name in ring:
            joints[i] = blend(i, ring[name][0])
            conf[i] = ring[name][1]
            measured[i] = True
        elif pred is not None and np.isfinite(pred[i]).all():
            joints[i] = pred[i]
            conf[i] = 0.3
        else:  # Between the modes of the two parts that meet there.
            pa, pb, _ = RING_JOINTS[name]
            between = 0.5 * (modes[_P[pa]] + modes[_P[pb]])
            if np.isfinite(between).all():
                joints[i] = _ref_push(between, RING_JOINTS[name][2])
                conf[i] = 0.2

    modes_back = modes + PART_RADII[:, None] * (
        modes / np.maximum(np.linalg.norm(modes, axis=1, keepdims=True), 1e-9)
    )
    for anchor_name, part_name, joint_name in _LIMBS:
        ia, part, ij = _J[anchor_name], _P[part_name], _J[joint_name]
        length = bone_lengths[ij] if JOINT_PARENTS[ij] == ia else bone_lengths[ia]
        anchor = joints[ia]
        direction = np.full(3, np.nan)
        if np.isfinite(anchor).all() and counts[part] >= min_part_points:
            w_axis, w_ring = LIMB_DIRECTION_WEIGHTS[part_name.split("_", 1)[1]]
            to_mode = _ref_unit(modes_back[part] - anchor)
            if elong[part] >= min_elongation and np.isfinite(to_mode).all():
                axis = axes[part]
                towards = to_mode * np.linalg.norm(modes_back[part] - anchor)
                far = ring[joint_name][0] - anchor if joint_name in ring else np.full(3, np.nan)
                if np.isfinite(far).all():
                    towards = towards + far
                elif pred is not None and np.isfinite(pred[ij] - anchor).all():
                    towards = towards + PREDICTED_SIGN_WEIGHT * (pred[ij] - anchor)
                direction = axis if axis @ towards >= 0 else -axis
            else:
                direction = to_mode
            if joint_name in ring and w_ring > 0:
                to_ring = _ref_unit(ring[joint_name][0] - anchor)
                if np.isfinite(to_ring).all():
                    direction = _ref_unit(w_axis * direction + w_ring * to_ring)
        if np.isfinite(direction).all():
            value = anchor + length * direction
            if smoothing > 0 and pred is not None and np.isfinite(pred[ij]).all():
                value = (1.0 - smoothing) * value + smoothing * pred[ij]
                value = anchor + length * _ref_unit(value - anchor)
            joints[ij] = value
            conf[ij] = conf[ia] * min(1.0, counts[part] / 8.0)
            measured[ij] = measured[ia]
        elif pred is not None and np.isfinite(pred[ij]).all():
            if np.isfinite(anchor).all():
                base = pred[ia] if np.isfinite(pred[ia]).all() else anchor
                d = _ref_unit(pred[ij] - base)
                joints[ij] = anchor + length * d if np.isfinite(d).all() else pred[ij]
            else:
                joints[ij] = pred[ij]
            conf[ij] = 0.3 * max(conf[ia], 0.5)

    # Head: from the neck towards the head's mode.
    ih, ineck = _J["head"], _J["neck"]
    if np.isfinite(joints[ineck]).all() and counts[_P["head"]] >= 1:
        d = _ref_unit(modes_back[_P["head"]] - joints[ineck])
        if np.isfinite(d).all():
            joints[ih] = joints[ineck] + bone_lengths[ih] * d
            conf[ih] = min(1.0, counts[_P["head"]] / 8.0) * max(conf[ineck], 0.5)
            measured[ih] = True
    if not np.isfinite(joints[ih]).all() and pred is not None:
        joints[ih] = pred[ih]
        conf[ih] = 0.3
    # Torso: midpoint of neck and pelvis centre.
    it = _J["torso"]
    pelvis = 0.5 * (joints[_J["right_hip"]] + joints[_J["left_hip"]])
    joints[it] = 0.5 * (joints[ineck] + pelvis)
    if not np.isfinite(joints[it]).all() and pred is not None:
        joints[it] = pred[it]
    conf[it] = min(conf[ineck], conf[_J["right_hip"]], conf[_J["left_hip"]])
    measured[it] = measured[ineck] and measured[_J["right_hip"]] and measured[_J["left_hip"]]

    # Length agreement of measured ring-to-ring bones (health and confidence).
    ratio = np.full(15, np.nan)
    for child, parent in (
        ("right_hand", "right_elbow"),
        ("left_hand", "left_elbow"),
        ("right_foot", "right_knee"),
        ("left_foot", "left_knee"),
    ):
        if child in ring and parent in ring:
            dist = np.linalg.norm(ring[child][0] - ring[parent][0])
            ratio[_J[child]] = dist / max(bone_lengths[_J[child]], 1e-6)
            penalty = min(1.0, abs(ratio[_J[child]] - 1.0) / 0.5)
            conf[_J[child]] *= 1.0 - 0.5 * penalty
    conf = np.where(np.isfinite(joints).all(axis=1), np.clip(conf, 0.0, 1.0), 0.0)
    return SkeletonFit(joints=joints, confidence=conf, measured=measured, length_ratio=ratio)


def _ref_bone_anchors(joints: np.ndarray, bone_lengths: np.ndarray, *, n: int = 3) -> np.ndarray:
    j = np.asarray(joints, dtype=float)
    pelvis = 0.5 * (j[_J["right_hip"]] + j[_J["left_hip"]])
    starts = np.full((N_PARTS, 3), np.nan)
    ends = np.full((N_PARTS, 3), np.nan)
    starts[_P["head"]], ends[_P["head"]] = j[_J["neck"]], j[_J["head"]]
    starts[_P["upper_torso"]], ends[_P["upper_torso"]] = j[_J["neck"]], j[_J["torso"]]
    starts[_P["lower_torso"]], ends[_P["lower_torso"]] = j[_J["torso"]], pelvis
    for side in ("right", "left"):
        sh, el, wr = j[_J[f"{side}_shoulder"]], j[_J[f"{side}_elbow"]], j[_J[f"{side}_hand"]]
        hip, kn, an = j[_J[f"{side}_hip"]], j[_J[f"{side}_knee"]], j[_J[f"{side}_foot"]]
        for part, a, b in (
            ("upper_arm", sh, el),
            ("forearm", el, wr),
            ("thigh", hip, kn),
            ("shank", kn, an),
        ):
            starts[_P[f"{side}_{part}"]], ends[_P[f"{side}_{part}"]] = a, b
        hand_len = 0.74 * bone_lengths[_J[f"{side}_hand"]]
        starts[_P[f"{side}_hand"]] = wr
        ends[_P[f"{side}_hand"]] = wr + hand_len * _ref_unit(wr - el)
        starts[_P[f"{side}_foot"]] = an
        ends[_P[f"{side}_foot"]] = an + 0.1 * bone_lengths[_J[f"{side}_foot"]] * _ref_unit(an - kn)
    t = (np.arange(n) + 0.5) / n
    return starts[:, None, :] + t[None, :, None] * (ends - starts)[:, None, :]


def _assert_same(new, ref):
    """Bit-for-bit equality of arrays (NaN where NaN), tuples, dicts and SkeletonFit."""
    if isinstance(ref, SkeletonFit):
        for field in ("joints", "confidence", "measured", "length_ratio"):
            _assert_same(getattr(new, field), getattr(ref, field))
    elif isinstance(ref, dict):
        assert new.keys() == ref.keys()
        for key in ref:
            _assert_same(new[key], ref[key])
    elif isinstance(ref, tuple):
        assert len(new) == len(ref)
        for a, b in zip(new, ref, strict=True):
            _assert_same(a, b)
    else:
        new, ref = np.asarray(new), np.asarray(ref)
        assert new.dtype == ref.dtype and new.shape == ref.shape
        np.testing.assert_array_equal(new, ref, strict=True)


def _random_case(rendered, seed):
    """A frame's points and labels with random damage, and the fit's other inputs."""
    rng = np.random.default_rng(seed)
    points, labels = _frame_points(rendered, int(rng.integers(0, 150)))
    labels = labels.copy()
    flip = rng.random(len(labels)) < rng.choice([0.0, 0.05, 0.3])
    labels[flip] = rng.integers(-1, N_PARTS, size=flip.sum())
    for part in rng.choice(N_PARTS, size=rng.integers(0, 5), replace=False):
        labels[labels == part] = -1 if rng.random() < 0.5 else rng.integers(0, N_PARTS)
    graph = geodesic_graph(points)
    bones = prior_bone_lengths(rng.uniform(1.4, 1.95))
    truth = rendered.reference.joints[0]
    prediction = None
    if rng.random() < 0.7:
        prediction = truth + rng.normal(scale=0.03, size=truth.shape)
        prediction[rng.random(15) < 0.2] = np.nan
    modes = None if rng.random() < 0.5 else part_modes(points, labels, bandwidth=0.06)
    options = {
        "bone_lengths": bones,
        "edges": (graph.rows, graph.cols),
        "modes": modes,
        "prediction": prediction,
        "height": None if rng.random() < 0.3 else rng.uniform(1.4, 1.95),
        "smoothing": float(rng.choice([0.0, 0.3, 0.6])),
        "min_elongation": float(rng.choice([3.0, 1.5, 50.0])),
    }
    return points, labels, options


@pytest.mark.parametrize("seed", range(24))
def test_fast_fit_matches_the_original_bit_for_bit(rendered, seed):
    points, labels, options = _random_case(rendered, seed)
    # The reference is the fit before the trunk anchors the shoulders (tested apart).
    fast = fit_skeleton(points, labels, shoulder_anchor=0.0, **options)
    _assert_same(fast, _ref_fit_skeleton(points, labels, **options))
    rows, cols = options["edges"]
    centres, counts = part_boundaries(points, labels, rows, cols)
    _assert_same((centres, counts), _ref_part_boundaries(points, labels, rows, cols))
    for min_points in (1, 4, 30):
        _assert_same(
            part_axes(points, labels, min_points=min_points),
            _ref_part_axes(points, labels, min_points=min_points),
        )
    for min_edges, shift in ((1, 0.0), (2, 0.0), (6, 0.0), (2, 0.035)):
        _assert_same(
            ring_joints(centres, counts, height=1.7, min_edges=min_edges, elbow_shift=shift),
            _ref_ring_joints(centres, counts, height=1.7, min_edges=min_edges, elbow_shift=shift),
        )
    joints = fit_skeleton(points, labels, **options).joints
    for n in (1, 3):
        _assert_same(
            bone_anchors(joints, options["bone_lengths"], n=n),
            _ref_bone_anchors(joints, options["bone_lengths"], n=n),
        )


def test_fast_fit_matches_the_original_on_random_clouds():
    rng = np.random.default_rng(7)
    for _ in range(30):
        n = int(rng.integers(20, 500))
        points = rng.normal(scale=0.4, size=(n, 3)) + [0.0, 0.0, 2.5]
        labels = rng.integers(-1, N_PARTS + 1, size=n)  # includes out-of-range labels
        rows, cols = rng.integers(0, n, size=(2, 6 * n))
        bones = prior_bone_lengths(1.75)
        prediction = rng.normal(scale=0.5, size=(15, 3)) + [0.0, 0.0, 2.5]
        kwargs = {"bone_lengths": bones, "edges": (rows, cols), "prediction": prediction}
        kwargs["smoothing"] = 0.3
        _assert_same(
            fit_skeleton(points, labels, shoulder_anchor=0.0, **kwargs),
            _ref_fit_skeleton(points, labels, **kwargs),
        )
        _assert_same(part_axes(points, labels), _ref_part_axes(points, labels))
        centres, counts = part_boundaries(points, labels, rows, cols)
        _assert_same((centres, counts), _ref_part_boundaries(points, labels, rows, cols))
        _assert_same(
            ring_joints(centres, counts, height=1.6, min_edges=1),
            _ref_ring_joints(centres, counts, height=1.6, min_edges=1),
        )
        joints = rng.normal(size=(15, 3))
        joints[rng.integers(0, 15)] = np.nan
        _assert_same(bone_anchors(joints, bones), _ref_bone_anchors(joints, bones))


def _one_forearm(mode_offset: float, seen_wrist: bool):
    """Inputs of ``_place_limbs`` with only the right forearm seen, running down-right.

    Its principal axis points up-left (PCA's sign is arbitrary); its mode lies
    ``mode_offset`` metres along the true direction from the elbow; the wrist's
    ring joint, where seen, 25 cm along it.
    """
    true = np.array([1.0, -1.0, 0.0]) / np.sqrt(2.0)
    elbow = np.array([0.2, 0.1, 2.0])
    part = _P["right_forearm"]
    joints = np.full((15, 3), np.nan)
    joints[J["right_elbow"]] = elbow
    modes = np.full((N_PARTS, 3), np.nan)
    modes[part] = elbow + mode_offset * true
    axes = np.full((N_PARTS, 3), np.nan)
    axes[part] = -true
    counts, elong = np.zeros(N_PARTS, dtype=int), np.zeros(N_PARTS)
    counts[part], elong[part] = 30, 6.0
    ring = {"right_hand": (elbow + 0.25 * true, 1.0)} if seen_wrist else {}
    kwargs = dict(
        bone_lengths=prior_bone_lengths(1.75),
        counts=counts,
        modes=modes,
        modes_back=modes,
        boundaries=np.full((N_PARTS, N_PARTS, 3), np.nan),
        exits=np.full((N_PARTS, 3), np.nan),
        axes=axes,
        elong=elong,
        ring=ring,
        pred=None,
        smoothing=0.0,
        min_part_points=4,
        min_elongation=3.0,
    )
    return joints, kwargs, elbow, true


@pytest.mark.parametrize(
    ("mode_offset", "seen_wrist"),
    [(0.12, False), (0.12, True), (-0.035, True)],  # the last: a mode behind the elbow
)
def test_limb_axis_turns_towards_the_far_end_it_sees(mode_offset, seen_wrist):
    joints, kwargs, elbow, true = _one_forearm(mode_offset, seen_wrist)
    conf, measured = np.ones(15), np.ones(15, dtype=bool)
    _place_limbs(joints, conf, measured, **kwargs)
    hand = joints[J["right_hand"]]
    length = kwargs["bone_lengths"][J["right_hand"]]
    assert np.isclose(np.linalg.norm(hand - elbow), length, atol=1e-9)
    assert np.linalg.norm(hand - (elbow + length * true)) < 1e-3  # within a millimetre
    assert np.isnan(joints[J["left_hand"]]).all()  # unseen limbs are left alone


def test_limb_axis_sign_follows_the_prediction_where_the_far_end_is_unseen():
    # A forearm pointing at the camera: its mode lies behind the (pushed-back) elbow and
    # its wrist is not seen, so the evidence alone turns the axis end for end; the
    # predicted hand, 25 cm along the true direction, decides the sign, and only that:
    # the hand follows the measured axis, not the prediction.
    joints, kwargs, elbow, true = _one_forearm(-0.035, seen_wrist=False)
    alone = joints.copy()
    _place_limbs(alone, np.ones(15), np.ones(15, dtype=bool), **kwargs)
    length = kwargs["bone_lengths"][J["right_hand"]]
    assert np.linalg.norm(alone[J["right_hand"]] - (elbow - length * true)) < 1e-3
    pred = np.full((15, 3), np.nan)
    pred[J["right_elbow"]] = elbow
    pred[J["right_hand"]] = elbow + 0.25 * (true + [0.0, 0.0, 0.3])  # roughly along it
    kwargs["pred"] = pred
    _place_limbs(joints, np.ones(15), np.ones(15, dtype=bool), **kwargs)
    assert np.linalg.norm(joints[J["right_hand"]] - (elbow + length * true)) < 1e-3
    # Evidence with a long baseline (the wrist's ring joint) still outweighs it.
    joints, kwargs, elbow, true = _one_forearm(0.12, seen_wrist=True)
    kwargs["pred"] = np.where(np.isfinite(pred), 2 * elbow - pred, np.nan)  # a flipped guess
    _place_limbs(joints, np.ones(15), np.ones(15, dtype=bool), **kwargs)
    assert np.linalg.norm(joints[J["right_hand"]] - (elbow + length * true)) < 1e-3


def test_elbows_are_moved_off_their_boundary_down_the_arm(rendered):
    # With true labels the upper-arm/forearm boundary lies a few centimetres up the
    # upper arm once the arm bends; the fit's elbows are moved down the arm towards
    # the joint, by less where the arm is nearly straight. (From frame 40, once the
    # motion has left its T-pose, where the boundary is 5-10 mm from the elbow.)
    bones = _true_bones(rendered.reference.joints[0])
    at_boundary, fitted = [], []
    for i in range(40, 150, 5):
        points, labels = _frame_points(rendered, i)
        graph = geodesic_graph(points)
        truth = rendered.reference.joints[i]
        centres, counts = part_boundaries(points, labels, graph.rows, graph.cols)
        ring = ring_joints(centres, counts, height=1.75)
        fit = fit_skeleton(points, labels, bone_lengths=bones, edges=(graph.rows, graph.cols))
        for side in ("right", "left"):
            elbow = truth[J[f"{side}_elbow"]]
            down = elbow - truth[J[f"{side}_shoulder"]]
            down /= np.linalg.norm(down)
            if f"{side}_elbow" in ring:
                at_boundary.append((ring[f"{side}_elbow"][0] - elbow) @ down)
                fitted.append((fit.joints[J[f"{side}_elbow"]] - elbow) @ down)
    assert len(fitted) >= 30
    assert np.median(at_boundary) < -0.025  # the boundary: more than 2.5 cm up the arm
    assert -0.02 < np.median(fitted) < 0.005  # the fit's elbow: within 2 cm, never past
    assert np.median(fitted) - np.median(at_boundary) > 0.01  # at least 1 cm nearer


def test_straight_arms_keep_their_elbows_at_the_boundary():
    # A T-pose's arm: the boundary lies at the elbow, and the elbow stays there (within
    # 3 mm, a tenth of the full shift: the push-back along each boundary's own ray bends
    # the line a little).
    centres = np.full((N_PARTS, N_PARTS, 3), np.nan)
    counts = np.zeros((N_PARTS, N_PARTS), dtype=int)
    for name, x in (("right_shoulder", 0.2), ("right_elbow", 0.45), ("right_hand", 0.7)):
        a, b, _ = RING_JOINTS[name]
        centres[_P[a], _P[b]] = centres[_P[b], _P[a]] = [x, 0.3, 2.5]
        counts[_P[a], _P[b]] = counts[_P[b], _P[a]] = 6
    still = ring_joints(centres, counts, height=1.75)["right_elbow"][0]
    moved = ring_joints(centres, counts, height=1.75, elbow_shift=0.035)["right_elbow"][0]
    assert np.linalg.norm(moved - still) < 0.003
    # Bent at a right angle at the elbow: moved the full shift, away from the shoulder.
    a, b, _ = RING_JOINTS["right_hand"]
    centres[_P[a], _P[b]] = centres[_P[b], _P[a]] = [0.45, 0.05, 2.5]
    still = ring_joints(centres, counts, height=1.75)["right_elbow"][0]
    moved = ring_joints(centres, counts, height=1.75, elbow_shift=0.035)["right_elbow"][0]
    assert 30.0 <= ELBOW_FULL_SHIFT_BEND <= 90.0
    assert np.isclose(np.linalg.norm(moved - still), 0.035, atol=1e-9)
    assert moved[0] > still[0]  # down the arm: further from the shoulder (x = 0.2)
