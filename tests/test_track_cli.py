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
    assert len(list((out / "figures").glob("*.png"))) == 4  # Fig. 9, 6, 12, Bland-Altman
    assert (out / "figures" / "bland_altman.png").stat().st_size > 0


def test_track_and_view_a_synth_folder(sequence, tmp_path):
    """The documented ``posedrift synth ... --out s1 && posedrift track s1`` works."""
    from posedrift.synthetic import contact_sheet, write_synthetic

    synth = tmp_path / "s1"
    write_synthetic(sequence, synth)
    contact_sheet(sequence, synth / "contact_sheet.png")  # 8-bit RGB beside depth/
    out = tmp_path / "p1"
    result = runner.invoke(
        app,
        ["-q", "track", str(synth), "--out", str(out), "--no-video", "--no-viewer"]
        + ["--point-clouds", "ply"],
    )
    assert result.exit_code == 0, result.output
    data = json.loads((out / "poses.json").read_text())
    assert len(data["frames"]) == len(sequence.frames)
    est = np.array([f["joints"] for f in data["frames"]], dtype=float)
    error = np.linalg.norm(est - sequence.reference.joints, axis=-1)
    assert np.median(error) < 0.10  # metres
    # the point clouds are summarised as a folder and a count, not a Python list
    assert f"points: {len(sequence.frames)} files in {out / 'points'}" in result.output
    assert "PosixPath" not in result.output and "[" not in result.output
    assert len(list((out / "points").glob("*.ply"))) == len(sequence.frames)
    view = runner.invoke(app, ["-q", "view", str(synth)])
    assert view.exit_code == 0, view.output
    assert f"{synth / 'depth'} (PngFolderSource)" in view.output
    assert f"{len(sequence.frames)} ({len(sequence.frames)} readable, 0 unreadable)" in view.output


def test_unusable_out_fails_up_front_naming_option_and_path(tmp_path, monkeypatch):
    import posedrift.io
    import posedrift.synthetic

    def no_work(*args, **kwargs):
        raise AssertionError("the input was read before the output path was checked")

    monkeypatch.setattr(posedrift.io, "open_depth_source", no_work)
    monkeypatch.setattr(posedrift.synthetic, "build_sequence", no_work)
    afile = tmp_path / "afile"
    afile.write_text("keep me")
    stack = str(tmp_path / "x.npy")
    cases = [
        (["track", stack, "--out", str(afile)], f"--out '{afile}' is an existing file"),
        (["track", stack, "--out", str(afile / "sub")], f"'{afile}' is a file, not a folder"),
        (["demo", "--out", str(afile)], f"--out '{afile}' is an existing file"),
        (["view", stack, "--out", str(afile / "x.gif")], f"'{afile}' is a file, not a folder"),
        (["view", stack, "--out", str(tmp_path / "bad.txt")], "must end in .gif or .mp4"),
        (["view", stack, "--out", str(tmp_path / "d.gif")], "is a folder, not a file"),
    ]
    (tmp_path / "d.gif").mkdir()
    for args, message in cases:
        result = runner.invoke(app, ["-q", *args])
        assert result.exit_code == 2, (args, result.output)
        assert message in result.output, (args, result.output)
        assert isinstance(result.exception, SystemExit)  # a usage error, no traceback
    assert afile.read_text() == "keep me"
    assert not (tmp_path / "bad.txt").exists()


def test_check_output_helpers(tmp_path):
    import os

    import typer

    from posedrift.cli._outputs import check_output_dir, check_output_file

    assert check_output_dir(tmp_path / "new" / "deeper", "--out") == tmp_path / "new" / "deeper"
    assert not (tmp_path / "new").exists()  # checked, not created
    assert check_output_dir(tmp_path, "--out") == tmp_path
    assert check_output_file(tmp_path / "a.GIF", "--json", suffixes=(".gif",)) == tmp_path / "a.GIF"
    (tmp_path / "f").write_text("")
    for check, path, option in [
        (check_output_dir, tmp_path / "f", "--out"),
        (check_output_dir, tmp_path / "f" / "x", "--figures"),
        (check_output_file, tmp_path / "f" / "r.json", "--json"),
        (check_output_file, tmp_path, "--json"),
    ]:
        with pytest.raises(typer.Exit) as info:
            check(path, option)
        assert info.value.exit_code == 2
    if os.geteuid() != 0:  # root may write anywhere
        locked = tmp_path / "locked"
        locked.mkdir(mode=0o500)
        with pytest.raises(typer.Exit):
            check_output_dir(locked / "out", "--out")


def test_all_nan_depth_is_reported_plainly(tmp_path):
    nan = tmp_path / "nan.npy"
    np.save(nan, np.full((3, 240, 320), np.nan, np.float32))
    negative = tmp_path / "neg.npy"
    np.save(negative, -np.ones((2, 240, 320)))
    for path in (nan, negative):
        view = runner.invoke(app, ["-q", "view", str(path)])
        assert view.exit_code == 2, view.output  # not usable, as an input that cannot be opened
        assert "no frame has valid depth" in view.output
        assert "inf" not in view.output
    out = tmp_path / "out"
    result = runner.invoke(app, ["-q", "track", str(nan), "--out", str(out), "--no-video"])
    assert result.exit_code == 0, result.output  # frames without a person are not an error
    assert "no pose recovered: no frame of" in result.output
    assert "has valid depth" in result.output
    frames = json.loads((out / "poses.json").read_text())["frames"]
    assert [f["status"] for f in frames] == ["no_person"] * 3


def test_unreadable_frame_message_names_the_file(tmp_path):
    rec = tmp_path / "rec"
    _write_png_folder(build_sequence(procedural_motion(), n_frames=3, name="s"), rec)
    (rec / "000001.png").write_bytes(b"\x89PNG\r\n\x1a\nnot really a png")
    out = tmp_path / "out"
    result = runner.invoke(app, ["-q", "track", str(rec), "--out", str(out), "--no-video"])
    assert result.exit_code == 1
    frame = json.loads((out / "poses.json").read_text())["frames"][1]
    assert frame["status"] == "lost"
    assert frame["message"].startswith(str(rec / "000001.png"))
    assert "cannot read this PNG" in frame["message"]
    row = read_poses(out / "poses.csv")[1]
    assert row["message"] == frame["message"]


def test_interrupted_track_says_so_and_keeps_what_was_done(sequence, tmp_path, monkeypatch):
    from posedrift.tracking import PoseTracker

    rec = tmp_path / "rec"
    _write_png_folder(sequence, rec)
    process = PoseTracker.process
    calls = []

    def interrupted_at_3(self, frame):
        calls.append(frame.index)
        if len(calls) == 4:
            raise KeyboardInterrupt
        return process(self, frame)

    monkeypatch.setattr(PoseTracker, "process", interrupted_at_3)
    out = tmp_path / "out"
    result = runner.invoke(app, ["-q", "track", str(rec), "--out", str(out), "--no-video"])
    assert result.exit_code == 130
    n = len(sequence.frames)
    assert f"interrupted at frame 3 of {n}" in result.output
    assert "hold the 3 frames processed so far" in result.output
    assert [f["index"] for f in json.loads((out / "poses.json").read_text())["frames"]] == [0, 1, 2]


def test_track_decimation_option(tmp_path):
    from posedrift.camera import camera_preset

    vga = camera_preset("kinect1-vga")
    seq = build_sequence(procedural_motion(), n_frames=3, intrinsics=vga, rng=0)
    stack = np.stack([np.rint(f.depth * 1000).astype(np.uint16) for f in seq.frames])
    np.save(tmp_path / "vga.npy", stack)
    joints = {}
    for option in ([], ["--decimation", "2"], ["--decimation", "1"]):
        out = tmp_path / ("o" + "".join(option))
        args = ["-q", "track", str(tmp_path / "vga.npy"), "--out", str(out), "--no-video"]
        result = runner.invoke(app, [*args, "--camera", "kinect1-vga", *option])
        assert result.exit_code == 0, result.output
        rows = read_poses(out / "poses.json")
        joints[tuple(option)] = np.array([r["joints"] for r in rows], dtype=float)
        assert np.isfinite(joints[tuple(option)]).all()
    # The default for a 640 x 480 camera is every other pixel.
    np.testing.assert_array_equal(joints[()], joints[("--decimation", "2")])
    bad = runner.invoke(
        app, ["track", str(tmp_path / "vga.npy"), "--out", "x", "--decimation", "0"]
    )
    assert bad.exit_code == 2 and "--decimation" in bad.output


def test_track_height_option_sets_the_stature(tmp_path):
    seq = build_sequence(procedural_motion(), n_frames=2, rng=0)
    stack = np.stack([np.rint(f.depth * 1000).astype(np.uint16) for f in seq.frames])
    np.save(tmp_path / "d.npy", stack)
    widths = {}  # neck to head, metres
    for height in ("1.5", "2.0"):
        out = tmp_path / height
        args = ["-q", "track", str(tmp_path / "d.npy"), "--out", str(out), "--no-video"]
        result = runner.invoke(app, [*args, "--camera", "kinect1-qvga", "--height", height])
        assert result.exit_code == 0, result.output
        joints = np.array(read_poses(out / "poses.json")[0]["joints"], dtype=float)
        head, neck = JOINT_NAMES.index("head"), JOINT_NAMES.index("neck")
        widths[height] = np.linalg.norm(joints[head] - joints[neck])
    # The neck-to-head bone is the stature's share (the limbs are measured): it follows
    # the stature given.
    assert widths["2.0"] / widths["1.5"] == pytest.approx(2.0 / 1.5, rel=1e-6)
    bad = runner.invoke(app, ["track", str(tmp_path / "d.npy"), "--out", "x", "--height", "9"])
    assert bad.exit_code == 2 and "--height" in bad.output


def test_millimetres_read_as_metres_get_a_hint(tmp_path):
    """A float stack in millimetres: view and track say to give --depth-scale."""
    stack = np.zeros((2, 240, 320), np.float32)
    stack[:, 60:200, 130:190] = 2800.0  # a person-sized block, in millimetres
    path = tmp_path / "mm.npy"
    np.save(path, stack)
    view = runner.invoke(app, ["-q", "view", str(path)])
    assert view.exit_code == 0, view.output
    assert "depths of 2800 m look like raw sensor units" in view.output
    assert "--depth-scale (1000 for millimetres)" in view.output
    out = tmp_path / "out"
    track = runner.invoke(app, ["-q", "track", str(path), "--out", str(out), "--no-video"])
    assert "no pose recovered" in track.output
    assert "its depths of 2800 m look like raw sensor units" in track.output
    # given the scale, the same stack reads as a plausible 2.8 m and gets no hint
    view = runner.invoke(app, ["-q", "view", str(path), "--depth-scale", "1000"])
    assert "2.800 - 2.800 m" in view.output
    assert "raw sensor units" not in view.output
