"""Outputs: poses.json / poses.csv / poses.bvh and point clouds, read back."""

from __future__ import annotations

import json
import logging

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from posedrift.camera import camera_preset
from posedrift.io import (
    CSV_COLUMNS,
    bvh_to_camera,
    read_point_cloud,
    read_poses,
    write_bvh,
    write_point_clouds,
    write_poses,
)
from posedrift.skeleton import ANGLE_NAMES, JOINT_NAMES, JOINT_PARENTS, t_pose_joints
from posedrift.tracking import FrameResult, FrameStatus

QVGA = camera_preset("kinect1-qvga")
_TO_CAMERA = np.array([1.0, -1.0, -1.0])  # body frame (Y up, facing +Z) -> facing the camera


def _parents_first() -> list[int]:
    order, todo = [], [JOINT_PARENTS.index(-1)]
    while todo:
        j = todo.pop()
        order.append(j)
        todo.extend(c for c, p in enumerate(JOINT_PARENTS) if p == j)
    return order


def random_poses(n: int, rng: int = 0, spread: float = 0.6) -> np.ndarray:
    """``(n, 15, 3)`` camera-frame poses with constant bone lengths, ~2.8 m away."""
    rng = np.random.default_rng(rng)
    rest = t_pose_joints(1.75)
    out = np.zeros((n, 15, 3))
    for t in range(n):
        for j in _parents_first():
            p = JOINT_PARENTS[j]
            if p < 0:
                out[t, j] = rest[j]
                continue
            turn = Rotation.from_rotvec(rng.normal(0.0, spread, 3)).as_matrix()
            out[t, j] = out[t, p] + turn @ (rest[j] - rest[p])
    return out * _TO_CAMERA + np.array([0.05, 0.9, 2.8])


def make_results(joints: np.ndarray, *, lost=(), rng: int = 0) -> list[FrameResult]:
    rng = np.random.default_rng(rng)
    results = []
    for i, frame in enumerate(joints):
        if i in lost:
            results.append(
                FrameResult.empty(i, FrameStatus.LOST, "no person, said the test", timestamp=i / 30)
            )
            continue
        points = frame[rng.integers(0, 15, 60)] + rng.normal(0, 0.03, (60, 3))
        results.append(
            FrameResult(
                i,
                FrameStatus.TRACKED if i else FrameStatus.REINITIALIZED,
                frame,
                np.linspace(0.5, 1.0, 15),
                points=points,
                labels=rng.integers(0, 15, 60),
                timestamp=i / 30,
            )
        )
    return results


def _bvh_world_joints(path, n_frames: int) -> tuple[np.ndarray, dict[str, str | None]]:
    bvhio = pytest.importorskip("bvhio")
    root = bvhio.readAsHierarchy(str(path))
    layout = [joint for joint, _, _ in root.layout()]
    parents = {j.Name: (j.Parent.Name if j.Parent is not None else None) for j in layout}
    out = np.zeros((n_frames, 15, 3))
    for f in range(n_frames):
        root.loadPose(f, recursive=True)
        positions = {j.Name: np.array(j.PositionWorld) for j in layout}
        out[f] = bvh_to_camera(np.array([positions[n] for n in JOINT_NAMES]))
    return out, parents


def test_json_schema_and_round_trip(tmp_path):
    joints = random_poses(6)
    results = make_results(joints, lost={2})
    paths = write_poses(results, tmp_path / "out", intrinsics=QVGA)
    assert set(paths) == {"json", "csv", "bvh"} and all(p.exists() for p in paths.values())
    doc = json.loads(paths["json"].read_text())
    assert doc["intrinsics"] == QVGA.to_dict()
    assert doc["joint_names"] == list(JOINT_NAMES) and doc["angle_names"] == list(ANGLE_NAMES)
    assert doc["fps"] == pytest.approx(30.0)
    frames = doc["frames"]
    assert [f["status"] for f in frames] == [
        "reinitialized",
        "tracked",
        "lost",
        "tracked",
        "tracked",
        "tracked",
    ]
    assert frames[2]["joints"] == [None] * 15 and frames[2]["bvh_pose"] == "held"
    assert frames[2]["message"] == "no person, said the test"
    assert frames[1]["bvh_pose"] == "recovered"
    np.testing.assert_allclose(frames[4]["joints"], joints[4])
    assert frames[4]["angles_deg"] == pytest.approx(
        dict(zip(ANGLE_NAMES, results[4].angles, strict=True))
    )
    assert read_poses(tmp_path / "out") == frames


def test_csv_matches_json(tmp_path):
    results = make_results(random_poses(4), lost={0})
    paths = write_poses(results, tmp_path, intrinsics=QVGA, fps=25)
    header = paths["csv"].read_text().splitlines()[0].split(",")
    assert tuple(header) == CSV_COLUMNS and "head_x" in header and "left_knee_deg" in header
    from_csv = read_poses(paths["csv"])
    from_json = read_poses(paths["json"])
    assert len(from_csv) == 4
    for a, b in zip(from_csv, from_json, strict=True):
        assert a["index"] == b["index"] and a["status"] == b["status"]
        assert a["bvh_pose"] == b["bvh_pose"] and a.get("message") == b.get("message")
        assert a["timestamp"] == pytest.approx(b["timestamp"])
        for ja, jb in zip(a["joints"], b["joints"], strict=True):
            assert (ja is None and jb is None) or ja == pytest.approx(jb, abs=1e-12)
        assert a["angles_deg"] == b["angles_deg"]
        assert a["confidence"] == pytest.approx(b["confidence"])
    assert from_csv[0]["bvh_pose"] == "held"  # before the first pose: the first known one


def test_bvh_forward_kinematics_reproduce_joints(tmp_path):
    joints = random_poses(12, rng=3)
    results = make_results(joints, lost={5})
    paths = write_poses(results, tmp_path, intrinsics=QVGA)
    fk, parents = _bvh_world_joints(paths["bvh"], len(joints))
    assert set(parents) == set(JOINT_NAMES)  # exactly the 15 joints
    for j, p in enumerate(JOINT_PARENTS):
        assert parents[JOINT_NAMES[j]] == (JOINT_NAMES[p] if p >= 0 else None)
    expected = joints.copy()
    expected[5] = joints[4]  # held frame: the last known pose
    error = np.linalg.norm(fk - expected, axis=-1)
    assert error.max() < 1e-4  # metres; the target is 1 cm
    text = paths["bvh"].read_text()
    assert "Frame Time: 0.03333333" in text and "Frames: 12" in text


def test_bvh_identity_t_pose_and_varying_lengths(tmp_path):
    still = np.repeat((t_pose_joints(1.6) * _TO_CAMERA + [0, 0.8, 3.0])[None], 3, axis=0)
    path, held = write_bvh(still, tmp_path / "still.bvh")
    fk, _ = _bvh_world_joints(path, 3)
    np.testing.assert_allclose(fk, still, atol=1e-5)
    assert not held.any()
    motion = path.read_text().split("Frame Time:")[1].splitlines()[1:]
    values = np.array([[float(v) for v in row.split()] for row in motion])
    np.testing.assert_allclose(values[0], values[2])
    # Constant limb lengths: rotations only below the shoulders and hips.
    trunk = ("torso", "neck", "head", "right_shoulder", "left_shoulder", "right_hip", "left_hip")
    assert text_channels(path) == dict.fromkeys(trunk, 6)
    # Lengths that vary by centimetres (a joint convention's offsets): those joints get
    # position channels and are reproduced exactly; sub-tolerance variation stays
    # within the tolerance.
    rng = np.random.default_rng(0)
    joints = random_poses(10, rng=5)
    joints[:, JOINT_NAMES.index("left_hand")] += rng.normal(0, 0.03, (10, 3))
    joints[:, JOINT_NAMES.index("right_knee")] += rng.normal(0, 0.001, (10, 3))
    path, _ = write_bvh(joints, tmp_path / "stretchy.bvh")
    fk, _ = _bvh_world_joints(path, 10)
    error = np.linalg.norm(fk - joints, axis=-1)
    assert error[:, JOINT_NAMES.index("left_hand")].max() < 1e-5
    assert error.max() < 0.005  # metres: the default length_tolerance
    channels = text_channels(path)
    assert channels["left_hand"] == 6 and "right_knee" not in channels


def text_channels(path) -> dict[str, int]:
    """The joints of a BVH file with more than three channels, and how many."""
    out, name = {}, None
    for line in path.read_text().split("MOTION")[0].splitlines():
        words = line.split()
        if words and words[0] in ("ROOT", "JOINT"):
            name = words[1]
        elif words and words[0] == "CHANNELS" and int(words[1]) > 3:
            out[name] = int(words[1])
    return out


def test_no_pose_at_all_skips_bvh_with_a_warning(tmp_path, caplog):
    results = [FrameResult.empty(i, FrameStatus.NO_PERSON, "empty room") for i in range(3)]
    with caplog.at_level(logging.WARNING, logger="posedrift.io"):
        paths = write_poses(results, tmp_path, intrinsics=QVGA)
    assert "bvh" not in paths and not (tmp_path / "poses.bvh").exists()
    assert "No frame has a complete pose" in caplog.text
    assert {f["bvh_pose"] for f in read_poses(paths["json"])} == {"none"}
    with pytest.raises(ValueError, match="No frame has a complete pose"):
        write_bvh(np.full((2, 15, 3), np.nan), tmp_path / "x.bvh")


def test_writer_errors(tmp_path):
    with pytest.raises(ValueError, match=r"'results' of write_poses must be FrameResult.*dict"):
        write_poses([{"index": 0}], tmp_path, intrinsics=QVGA)
    with pytest.raises(ValueError, match="'intrinsics' of write_poses must be an Intrinsics"):
        write_poses([], tmp_path, intrinsics=(1, 2, 3))
    with pytest.raises(ValueError, match=r"'fmt' of write_point_clouds must be 'npz' or 'ply'"):
        write_point_clouds([], tmp_path, fmt="obj")
    with pytest.raises(ValueError, match=r"shape \(T, 15, 3\)"):
        write_bvh(np.zeros((15, 3)), tmp_path / "x.bvh")
    with pytest.raises(FileNotFoundError, match="does not exist"):
        read_poses(tmp_path / "nothing.json")


@pytest.mark.parametrize("fmt", ["npz", "ply"])
def test_point_clouds_round_trip(tmp_path, fmt):
    results = make_results(random_poses(3), lost={1})
    paths = write_point_clouds(results, tmp_path / "points", fmt=fmt)
    assert [p.name for p in paths] == [f"00000{i}.{fmt}" for i in range(3)]
    for r, path in zip(results, paths, strict=True):
        points, labels = read_point_cloud(path)
        np.testing.assert_allclose(points, r.points, atol=1e-6)
        np.testing.assert_array_equal(labels, r.labels)
    if fmt == "ply":
        head = paths[0].read_bytes()[:400].decode("ascii", "replace")
        assert head.startswith("ply\nformat binary_little_endian 1.0")
        assert "element vertex 60" in head
