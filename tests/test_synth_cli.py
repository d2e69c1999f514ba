"""``posedrift synth`` and ``posedrift bench render`` through the CLI runner."""

from __future__ import annotations

import json

import numpy as np
import pytest
from typer.testing import CliRunner

from posedrift.cli import app
from posedrift.skeleton import ANGLE_NAMES, JOINT_NAMES, facing_yaw
from posedrift.synthetic import read_synthetic

runner = CliRunner()


def _run(*args: str):
    return runner.invoke(app, ["--quiet", *args])


def test_synth_builtin_writes_the_documented_folder(tmp_path):
    out = tmp_path / "walk"
    result = _run("synth", "builtin", "--out", str(out), "--frames", "3")
    assert result.exit_code == 0, result.output
    assert "wrote 3 frames" in result.output
    truth = json.loads((out / "ground_truth.json").read_text())
    assert set(truth) >= {"intrinsics", "fps", "joint_names", "angle_names", "frames"}
    assert truth["intrinsics"] == {
        "fx": 285.63,
        "fy": 285.63,
        "cx": 160.0,
        "cy": 120.0,
        "width": 320,
        "height": 240,
    }
    assert truth["fps"] == 30.0
    assert truth["joint_names"] == list(JOINT_NAMES)
    assert truth["angle_names"] == list(ANGLE_NAMES)
    assert len(truth["frames"]) == 3
    for i, frame in enumerate(truth["frames"]):
        assert frame["index"] == i
        assert np.array(frame["joints"], dtype=float).shape == (15, 3)
        assert set(frame["angles_deg"]) == set(ANGLE_NAMES)
    # Frame 0 is the calibration T-pose.
    t_pose = truth["frames"][0]["angles_deg"]
    assert t_pose["left_elbow"] == pytest.approx(180, abs=2)
    assert t_pose["left_shoulder"] == pytest.approx(90, abs=2)

    import imageio.v3 as iio

    for i in range(3):
        depth = iio.imread(out / "depth" / f"{i:06d}.png")
        labels = iio.imread(out / "labels" / f"{i:06d}.png")
        assert depth.dtype == np.uint16 and depth.shape == (240, 320)
        assert labels.dtype == np.uint8 and labels.shape == (240, 320)
        assert 2000 < np.median(depth[depth > 0]) < 3500  # millimetres, person ~2.8 m
        assert labels.max() <= 15 and np.array_equal(labels > 0, depth > 0)
    assert set(np.unique(iio.imread(out / "labels" / "000000.png"))) == set(range(16))
    assert (out / "contact_sheet.png").is_file()

    sequence = read_synthetic(out)
    assert len(sequence.frames) == 3 and sequence.reference.labels is not None


def test_synth_options_noise_background_camera_and_intrinsics(tmp_path):
    out = tmp_path / "noisy"
    result = _run(
        "synth", "builtin", "--out", str(out), "--frames", "2", "--noise", "--background",
        "--camera", "kinect1-vga", "--seed", "3", "--girth", "1.1",
    )  # fmt: skip
    assert result.exit_code == 0, result.output
    seq = read_synthetic(out)
    assert seq.frames[0].depth.shape == (480, 640)
    labels = seq.reference.labels[0]
    depth = seq.frames[0].depth
    assert np.count_nonzero((labels == 0) & (depth > 0)) > 10_000  # floor and wall
    out2 = tmp_path / "custom"
    result = _run(
        "synth", "builtin", "--out", str(out2), "--frames", "1",
        "--intrinsics", "200,200,80,60", "--size", "160x120", "--distance", "3.5",
    )  # fmt: skip
    assert result.exit_code == 0, result.output
    seq = read_synthetic(out2)
    assert seq.frames[0].intrinsics.fx == 200 and seq.frames[0].depth.shape == (120, 160)
    assert seq.reference.joints[0, JOINT_NAMES.index("torso"), 2] == pytest.approx(3.5, abs=0.05)


@pytest.mark.data
def test_synth_a_bvh_clip(mocap_dir, tmp_path):
    clip = mocap_dir / "cmu" / "002_05.bvh"
    if not clip.is_file():
        pytest.skip(f"{clip} not found")
    out = tmp_path / "bvh"
    result = _run("synth", str(clip), "--out", str(out), "--frames", "2")
    assert result.exit_code == 0, result.output
    seq = read_synthetic(out)
    assert len(seq.frames) == 2
    assert np.count_nonzero(seq.reference.labels[0]) > 2000


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--camera", "kinect9"], "Unknown camera preset 'kinect9'. Valid presets: kinect1-vga"),
        (["--intrinsics", "0,285,160,120"], "'fx' intrinsic"),
        (["--intrinsics", "285,285,400,120"], "'cx' intrinsic"),
        (["--intrinsics", "1,2,3"], "fx,fy,cx,cy"),
        (["--intrinsics", "285,285,160,120", "--size", "320by240"], "--size"),
        (["--camera", "d435", "--intrinsics", "1,1,1,1"], "either --camera or --intrinsics"),
        (["--girth", "-1"], "--girth must be greater than 0. Got -1."),
        (["--girth", "0"], "--girth must be greater than 0. Got 0."),
        (["--height", "9"], "--height must be in (0.5, 2.5). Got 9."),
        (["--height", "-1"], "--height must be in (0.5, 2.5). Got -1."),
        (["--distance", "0"], "--distance must be greater than 0. Got 0."),
        (["--fps", "-30"], "--fps must be greater than 0. Got -30."),
        (["--facing", "400"], "--facing must be in (-360, 360). Got 400."),
        (["--camera-tilt", "-90"], "--camera-tilt must be in (-90, 90). Got -90."),
        (["--size", "640x480"], "--size 640x480 goes with --intrinsics: the camera preset"),
        (["--camera", "d435", "--size", "512x424"], "give --camera kinect2, or --intrinsics"),
    ],
)
def test_synth_bad_options_fail_clearly(tmp_path, args, message):
    result = _run("synth", "builtin", "--out", str(tmp_path / "x"), "--frames", "1", *args)
    assert result.exit_code == 2
    assert message in result.stderr
    assert "'stature' parameter" not in result.output and "with_shape" not in result.output
    assert not (tmp_path / "x").exists()


def test_synth_facing_turns_the_person_away(tmp_path):
    out = tmp_path / "back"
    result = _run("synth", "builtin", "--out", str(out), "--frames", "2", "--facing", "180")
    assert result.exit_code == 0, result.output
    joints = np.asarray(json.loads((out / "ground_truth.json").read_text())["frames"][0]["joints"])
    assert abs(facing_yaw(joints) - 180.0) < 1.0


def test_synth_size_matching_the_preset_is_accepted(tmp_path):
    out = tmp_path / "vga"
    result = _run(
        "synth", "builtin", "--out", str(out), "-n", "1", "--camera", "d435", "--size", "640x480"
    )
    assert result.exit_code == 0, result.output
    assert read_synthetic(out).frames[0].intrinsics.fx == 385.0


def test_synth_person_out_of_view(tmp_path, monkeypatch):
    # No frame shows the person: fail, write nothing.
    out = tmp_path / "high"
    result = _run("synth", "builtin", "--out", str(out), "-n", "3", "--camera-height", "100")
    assert result.exit_code == 1
    assert "no frame shows the person" in result.stderr and "--camera-height 100 m" in result.stderr
    assert not out.exists()
    # Some frames without the person: written, with a warning that counts them.
    import dataclasses

    import posedrift.synthetic as synthetic

    build = synthetic.build_sequence

    def blank_frames_1_and_2(*args, **kwargs):
        seq = build(*args, **kwargs)
        labels = [
            np.zeros_like(lab) if i in (1, 2) else lab for i, lab in enumerate(seq.reference.labels)
        ]
        return dataclasses.replace(
            seq, reference=dataclasses.replace(seq.reference, labels=tuple(labels))
        )

    monkeypatch.setattr(synthetic, "build_sequence", blank_frames_1_and_2)
    out = tmp_path / "some"
    result = _run("synth", "builtin", "--out", str(out), "-n", "4")
    assert result.exit_code == 0, result.output
    assert "warning: 2 of 4 frames show no person (out of view): frames 1, 2." in result.stderr
    assert len(read_synthetic(out).frames) == 4


def test_synth_bad_source_names_the_file(tmp_path):
    missing = tmp_path / "nothere.bvh"
    result = _run("synth", str(missing), "--out", str(tmp_path / "x"))
    assert result.exit_code == 2
    assert f"error: {missing}: no such file (SOURCE is a BVH file or 'builtin')." in result.stderr
    result = _run("synth", str(tmp_path), "--out", str(tmp_path / "x"))
    assert f"error: {tmp_path}: not a file" in result.stderr
    bad = tmp_path / "bad.bvh"
    bad.write_bytes(b"\x00\xffnot a bvh")
    result = _run("synth", str(bad), "--out", str(tmp_path / "x"))
    assert result.exit_code != 0
    assert result.stderr.startswith(f"error: {bad}, line 1: a BVH file must start with")
    assert result.stderr.count("bad.bvh") == 1


# Two joints that no known rig names.
UNMAPPABLE_BVH = """HIERARCHY
ROOT node0
{
  OFFSET 0 0 0
  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
  JOINT node1
  {
    OFFSET 0 10 0
    CHANNELS 3 Zrotation Xrotation Yrotation
    End Site
    {
      OFFSET 0 10 0
    }
  }
}
MOTION
Frames: 2
Frame Time: 0.0333333
0 90 0 0 0 0 0 0 0
0 90 0 0 0 0 0 0 0
"""


def test_synth_unmappable_rig_says_what_to_do_on_the_command_line(tmp_path):
    clip = tmp_path / "renamed.bvh"
    clip.write_text(UNMAPPABLE_BVH)
    result = _run("synth", str(clip), "--out", str(tmp_path / "x"))
    assert result.exit_code == 2
    assert f"error: {clip}: cannot map the skeleton to the 15 joints" in result.stderr
    assert "The file's joints are: node0, node1." in result.stderr
    assert "Pass rig=" not in result.stderr
    assert result.stderr.rstrip().endswith(
        "Rename the file's joints to the names looked for, or map them in Python: "
        "posedrift.synthetic.bvh_motion(path, rig={joint name: node name})."
    )


def test_bench_render_reports_both_timings(tmp_path, monkeypatch):
    result = _run(
        "bench", "render", "--repeats", "1", "--frames", "2", "--json", str(tmp_path / "b.json")
    )
    assert result.exit_code == 0, result.output
    assert "rendering only" in result.output and "posing + rendering" in result.output
    data = json.loads((tmp_path / "b.json").read_text())
    assert data["render_ms"] > 0 and data["pose_and_render_ms"] >= data["render_ms"] * 0.5
    assert data["width"] == 320 and data["height"] == 240 and data["frames"] == 2
    assert data["mean_person_pixels"] > 2000
