"""``posedrift track`` and ``posedrift demo`` end to end, reading back what they wrote."""

from __future__ import annotations

import json

import imageio.v3 as iio
import numpy as np
import pytest
from typer.testing import CliRunner

from posedrift.cli import app
from posedrift.io import read_poses
from posedrift.skeleton import ANGLE_NAMES, JOINT_NAMES, to_convention
from posedrift.synthetic import build_sequence, procedural_motion

runner = CliRunner()


@pytest.fixture(scope="module")
def sequence():
    return build_sequence(procedural_motion(), n_frames=12, name="short")


def _write_png_folder(sequence, folder):
    folder.mkdir()
    for frame in sequence.frames:
        mm = np.round(frame.depth * 1000).astype(np.uint16)
        iio.imwrite(folder / f"{frame.index:06d}.png", mm)


def test_track_png_folder_writes_every_output(sequence, tmp_path):
    _write_png_folder(sequence, tmp_path / "rec")
    out = tmp_path / "out"
    result = runner.invoke(app, ["-q", "track", str(tmp_path / "rec"), "--out", str(out)])
    assert result.exit_code == 0, result.output
    for name in ("poses.json", "poses.csv", "poses.bvh", "angles.png", "viewer.html"):
        assert (out / name).stat().st_size > 0, name
    assert (out / "tracking.gif").stat().st_size > 0
    data = json.loads((out / "poses.json").read_text())
    assert data["joint_names"] == list(JOINT_NAMES)
    assert data["angle_names"] == list(ANGLE_NAMES)
    assert len(data["frames"]) == len(sequence.frames)
    assert {f["status"] for f in data["frames"]} <= {"tracked", "reinitialized"}
    # The recovered joints are near the truth (metres, camera frame).
    est = np.array([f["joints"] for f in data["frames"]], dtype=float)
    error = np.linalg.norm(est - sequence.reference.joints, axis=-1)
    assert np.median(error) < 0.10
    assert len(read_poses(out / "poses.csv")) == len(sequence.frames)
    assert data["joint_convention"] == "native"
    # In the Kinect convention every output holds the moved joints, and says so.
    kinect = tmp_path / "kinect"
    result = runner.invoke(
        app,
        ["-q", "track", str(tmp_path / "rec"), "--out", str(kinect), "--no-video"]
        + ["--convention", "kinect"],
    )
    assert result.exit_code == 0, result.output
    moved = json.loads((kinect / "poses.json").read_text())
    assert moved["joint_convention"] == "kinect"
    moved_joints = np.array([f["joints"] for f in moved["frames"]], dtype=float)
    np.testing.assert_allclose(moved_joints, to_convention(est, "kinect"), atol=1e-9)
    csv_joints = np.array([r["joints"] for r in read_poses(kinect / "poses.csv")], dtype=float)
    np.testing.assert_allclose(csv_joints, moved_joints, atol=1e-6)
    bad = runner.invoke(app, ["track", str(tmp_path / "rec"), "--out", "o", "--convention", "x"])
    assert bad.exit_code != 0 and "Unknown --convention 'x'" in bad.output


def test_track_corrupt_frame_is_named_and_the_rest_processed(sequence, tmp_path):
    rec = tmp_path / "rec"
    _write_png_folder(sequence, rec)
    (rec / "000005.png").write_bytes(b"\x89PNG\r\n\x1a\nnot really a png")
    out = tmp_path / "out"
    result = runner.invoke(app, ["track", str(rec), "--out", str(out), "--no-video"])
    assert result.exit_code == 1
    assert "000005.png" in result.output
    frames = json.loads((out / "poses.json").read_text())["frames"]
    assert len(frames) == len(sequence.frames)
    assert frames[5]["status"] == "lost" and frames[5]["joints"][0] is None
    assert sum(f["status"] in ("tracked", "reinitialized") for f in frames) == len(frames) - 1


def test_track_bad_options_exit_2_and_name_the_choice(tmp_path):
    np.save(tmp_path / "d.npy", np.zeros((2, 240, 320), np.uint16))
    result = runner.invoke(app, ["track", str(tmp_path / "d.npy"), "--out", "o", "--camera", "x"])
    assert result.exit_code == 2
    assert "kinect1-qvga" in result.output
    missing = runner.invoke(app, ["track", str(tmp_path / "none.npy"), "--out", "o"])
    assert missing.exit_code == 2 and "none.npy" in missing.output


def test_track_frames_without_a_person(tmp_path):
    np.save(tmp_path / "empty.npy", np.zeros((3, 240, 320), np.uint16))
    out = tmp_path / "out"
    result = runner.invoke(app, ["-q", "track", str(tmp_path / "empty.npy"), "--out", str(out)])
    assert result.exit_code == 0, result.output
    frames = json.loads((out / "poses.json").read_text())["frames"]
    assert [f["status"] for f in frames] == ["no_person"] * 3


def test_demo_runs_and_writes_its_outputs(tmp_path):
    out = tmp_path / "demo"
    result = runner.invoke(
        app, ["-q", "demo", "--out", str(out), "--frames", "15", "--methods", "cpd,shotton"]
    )
    assert result.exit_code == 0, result.output
    assert "| cpd |" in result.output and "| shotton |" in result.output
    report = json.loads((out / "evaluation.json").read_text())
    assert report["frames"] == 15 and set(report["methods"]) == {"cpd", "shotton"}
    assert report["methods"]["cpd"]["angle_error_deg"]["mean"] < 15.0
    for name in ("poses.json", "angles.png", "tracking.gif", "viewer.html"):
        assert (out / name).stat().st_size > 0, name
    assert len(list((out / "figures").glob("*.png"))) == 3
