"""The evaluation harness and ``posedrift eval``: JSON schema, skipping, exit codes."""

import hashlib
import json

import numpy as np
import pytest
from typer.testing import CliRunner

import posedrift.evaluation._harness as harness
from posedrift.camera import DepthFrame, backproject, camera_preset, project
from posedrift.cli import app
from posedrift.evaluation import (
    EvaluationSequence,
    Reference,
    evaluate,
    markdown_table,
    parse_methods,
)
from posedrift.skeleton import ANGLE_NAMES, JOINT_NAMES, facing_yaw, joint_angles, t_pose_joints
from posedrift.tracking import FrameResult, FrameStatus

METHOD_KEYS = {
    "angle_error_deg",
    "mpjpe_mm",
    "map_10cm",
    "label_accuracy",
    "frames_per_second",
    "failed_frames",
}


class Centroid:
    """Test-only method: a T-pose standing at the silhouette's centroid."""

    name = "centroid"

    def __init__(self, intrinsics, *, forest=None):
        self.intrinsics = intrinsics

    def reset(self, intrinsics):
        self.intrinsics = intrinsics

    def process(self, frame):
        points, _ = backproject(frame.depth, frame.intrinsics)
        if len(points) == 0:
            return FrameResult.empty(frame.index, FrameStatus.NO_PERSON)
        body = t_pose_joints(1.75)[:, [0, 1, 2]] * [1, -1, 1]
        joints = body - body.mean(axis=0) + points.mean(axis=0)
        return FrameResult(frame.index, FrameStatus.TRACKED, joints, np.ones(15))


def _toy_sequence(n=6, name="toy"):
    k = camera_preset("kinect1-qvga")
    truth = t_pose_joints(1.75) * [1, -1, 1] + [0, 0.9, 3.0]
    frames = []
    for t in range(n):
        depth = np.zeros(k.shape, np.float32)
        depth[60:200, 140 + t : 180 + t] = 3.0
        frames.append(DepthFrame(depth, k, index=t))
    joints = np.repeat(truth[None], n, axis=0)
    labels = tuple(np.where(f.depth > 0, 2, 0).astype(np.uint8) for f in frames)
    ref = Reference(joints=joints, angles=joint_angles(joints), labels=labels)
    return EvaluationSequence(name=name, frames=tuple(frames), reference=ref)


class Offset:
    """Test-only: the reference (taken at construction, never from frames) moved by 5 cm,
    no pose on odd frames, and an exception on frame 4; its points all labelled part 1."""

    name = "offset"

    def __init__(self, truth):
        self.truth = truth

    def process(self, frame):
        if frame.index == 4:
            raise RuntimeError("boom")
        if frame.index % 2:
            return FrameResult.empty(frame.index, FrameStatus.LOST)
        pts, _ = backproject(frame.depth, frame.intrinsics)
        return FrameResult(
            frame.index,
            FrameStatus.TRACKED,
            self.truth + [0.05, 0, 0],
            np.ones(15),
            points=pts,
            labels=np.ones(len(pts), int),
        )


def test_harness_metrics_failures_and_label_accuracy():
    seq = _toy_sequence()
    truth = seq.reference.joints[0]
    report = evaluate(
        [seq],
        {"offset": lambda k, forest=None: Offset(truth), "centroid": Centroid},
        progress=False,
        forest=object(),
    )
    assert set(report) == {"protocol", "convention", "frames", "sequences", "methods"}
    assert report["protocol"] == "synthetic" and report["frames"] == 6
    assert report["convention"] == "native"
    row = report["methods"]["offset"]
    assert METHOD_KEYS <= set(row)
    assert row["failed_frames"] == 4  # frames 1, 3, 5 lost; frame 4 raised
    assert row["method_errors"] == 1
    assert row["mpjpe_mm"] == pytest.approx(50.0)
    assert row["map_10cm"] == 1.0
    assert row["angle_error_deg"]["mean"] == pytest.approx(0.0, abs=1e-9)
    assert row["label_accuracy"] == 1.0  # every point labelled part 1, truth label 2
    assert row["filled"]["mpjpe_mm"] == pytest.approx(50.0)
    assert row["frames_per_second"] > 0
    assert report["methods"]["centroid"]["failed_frames"] == 0
    # The toy person faces the camera in every frame. The skeleton 5 cm to the side of
    # the truth, 3 m away, sees the camera 0.95 degrees off its facing direction.
    front = row["by_view"]["front"]
    assert front["frames"] == 6 and front["angle_error_mean_deg"] == 0.0
    assert front["reference_facing_yaw_median_deg"] == pytest.approx(0.0, abs=1e-9)
    assert front["facing_yaw_median_deg"] == pytest.approx(
        np.degrees(np.arctan2(0.05, 3.0)), abs=1e-3
    )
    assert row["by_view"]["back"] == {
        "frames": 0,
        "angle_error_mean_deg": None,
        "facing_yaw_median_deg": None,
        "reference_facing_yaw_median_deg": None,
    }


class Still:
    """Test-only: the same skeleton (given at construction) in every frame."""

    name = "still"

    def __init__(self, joints):
        self.joints = joints

    def process(self, frame):
        return FrameResult(frame.index, FrameStatus.TRACKED, self.joints, np.ones(15))


def test_by_view_tells_a_skeleton_that_faces_the_camera_from_a_person_turned_away():
    seq = _toy_sequence()
    front = seq.reference.joints[0]
    pelvis = front[[9, 10]].mean(axis=0)
    back = (front - pelvis) * [-1, 1, -1] + pelvis  # turned 180 degrees about the vertical
    turned = np.repeat(back[None], len(seq.frames), axis=0)
    ref = Reference(joints=turned, angles=joint_angles(turned), labels=seq.reference.labels)
    seq = EvaluationSequence(name="turned", frames=seq.frames, reference=ref)
    report = evaluate(
        [seq],
        {"still": lambda k, forest=None: Still(front), "true": lambda k, forest=None: Still(back)},
        progress=False,
        forest=object(),
    )
    lagging = report["methods"]["still"]["by_view"]
    assert lagging["front"]["frames"] == 0 and lagging["front"]["facing_yaw_median_deg"] is None
    assert lagging["back"]["frames"] == 6
    assert lagging["back"]["reference_facing_yaw_median_deg"] == pytest.approx(180.0, abs=1e-6)
    assert lagging["back"]["facing_yaw_median_deg"] == pytest.approx(0.0, abs=1e-6)
    following = report["methods"]["true"]["by_view"]["back"]
    assert following["facing_yaw_median_deg"] == pytest.approx(180.0, abs=1e-6)
    assert following["angle_error_mean_deg"] == pytest.approx(0.0, abs=1e-9)


def test_in_view_splits_the_errors_on_angles_whose_joints_leave_the_image():
    seq = _toy_sequence()
    truth = seq.reference.joints[0]
    raised = np.repeat(truth[None], len(seq.frames), axis=0)
    hand = JOINT_NAMES.index("left_hand")
    raised[3:, hand] = truth[JOINT_NAMES.index("left_elbow")] + [0.0, -2.0, 0.0]  # above the top
    ref = Reference(joints=raised, angles=joint_angles(raised), labels=seq.reference.labels)
    seq = EvaluationSequence(name="raised", frames=seq.frames, reference=ref)
    report = evaluate(
        [seq], {"still": lambda k, forest=None: Still(truth)}, progress=False, forest=object()
    )
    row = report["methods"]["still"]
    # Only the left elbow's angle, in the last three of six frames, has a joint out of view:
    # the T-pose scores 0 on the angles in view and the hand's 90 degrees on the rest.
    assert row["in_view"] == {
        "angle_share": pytest.approx(1 - 3 / (6 * 8), abs=1e-4),
        "angle_error_mean_deg": 0.0,
        "out_of_view_angle_error_mean_deg": pytest.approx(90.0, abs=1e-3),
    }
    assert row["angle_error_deg"]["left_elbow"] == pytest.approx(45.0, abs=1e-3)
    text = markdown_table(report, paper=False)
    assert "6.2% of the reference's angles have a joint outside the image" in text
    # The same error as a bias: the T-pose reads that elbow straighter by 0 and 90 degrees.
    elbow = row["angle_agreement"]["left_elbow"]
    assert elbow["frames"] == 6 and elbow["bias_deg"] == pytest.approx(45.0, abs=1e-3)
    assert elbow["sd_deg"] == pytest.approx(np.sqrt(6 * 45.0**2 / 5), abs=1e-3)
    assert row["angle_agreement"]["right_knee"]["loa_high_deg"] == pytest.approx(0.0, abs=1e-9)
    assert "| still | +45.0 (-51.6, +141.6) | +0.0 (+0.0, +0.0) |" in text


def test_seen_splits_the_errors_on_angles_whose_joints_are_hidden():
    seq = _toy_sequence()
    k = seq.frames[0].intrinsics
    truth = seq.reference.joints[0]
    raised = np.repeat(truth[None], len(seq.frames), axis=0)
    hand = JOINT_NAMES.index("left_hand")
    raised[3:, hand] = truth[JOINT_NAMES.index("left_elbow")] + [0.0, -0.3, 0.0]
    u, v = np.rint(project(raised[3, hand][None], k)[0]).astype(int)
    frames = list(seq.frames)
    for t in range(3, 6):  # a board 40 cm in front of the raised hand
        depth = frames[t].depth.copy()
        depth[v - 3 : v + 4, u - 3 : u + 4] = 2.6
        frames[t] = DepthFrame(depth, k, index=t)
    ref = Reference(joints=raised, angles=joint_angles(raised), labels=seq.reference.labels)
    seq = EvaluationSequence(name="hidden", frames=tuple(frames), reference=ref)
    report = evaluate(
        [seq], {"still": lambda k, forest=None: Still(truth)}, progress=False, forest=object()
    )
    row = report["methods"]["still"]
    assert row["in_view"]["angle_share"] == 1.0
    seen = row["seen"]
    assert seen["angle_share"] == pytest.approx(1 - 3 / (6 * 8), abs=1e-4)
    assert seen["angle_error_deg"]["mean"] == 0.0
    assert seen["angle_error_deg"]["left_elbow"] == 0.0
    assert seen["hidden_angle_error_mean_deg"] == pytest.approx(90.0, abs=1e-3)
    per = row["per_sequence"]["hidden"]
    assert per["seen_angle_share"] == seen["angle_share"]
    assert per["seen_angle_error_mean_deg"] == 0.0
    text = markdown_table(report, paper=False)
    assert "6.2% of the reference's angles have a joint the frames do not show" in text
    assert "| still | 0.00 | 0.00 | 0.00 |" in text and "| 93.8% | 90.00 |" in text


def test_parse_methods():
    assert parse_methods("cpd, pda,cpd") == ["cpd", "pda"]
    with pytest.raises(ValueError, match="Unknown method\\(s\\) \\['nope'\\]. Valid methods: cpd"):
        parse_methods("cpd,nope")


def test_net_ablations_take_their_nets_from_the_shared_ones():
    """cpd-frontal keeps the frontal net alone, cpd-noback the nets without the back
    one, cpd-noside without the side one; each from the nets the run shares, or the
    shipped ones."""
    from posedrift.evaluation._harness import METHODS
    from posedrift.labelling import BodyPartNet, FacingNets

    K = camera_preset("kinect1-qvga")
    shipped = FacingNets.load_default()
    assert METHODS["cpd"][1](K, part_net=shipped).part_net.back is shipped.back
    assert METHODS["cpd-frontal"][1](K).part_net is shipped.frontal
    for shared in (None, shipped):
        nets = METHODS["cpd-noback"][1](K, part_net=shared).part_net
        assert nets.back is None and nets.turned is shipped.turned
        assert nets.frontal is shipped.frontal and nets.high is shipped.high
        nets = METHODS["cpd-noside"][1](K, part_net=shared).part_net
        assert nets.side is None and nets.back is shipped.back
        assert nets.turned is shipped.turned and nets.frontal is shipped.frontal
    assert METHODS["cpd-noback"][1](K).part_net.side is shipped.side
    alone = BodyPartNet.load_default()
    assert METHODS["cpd-noback"][1](K, part_net=alone).part_net is alone
    assert METHODS["cpd-noside"][1](K, part_net=alone).part_net is alone


class OracleForest:
    """Test-only: the ground-truth label images as the forest's prediction."""

    def __init__(self):
        self.table = {}

    def add(self, seq):
        for f, lab in zip(seq.frames, seq.reference.labels, strict=True):
            self.table[hashlib.sha1(f.depth.tobytes()).hexdigest()] = lab

    def predict(self, depth, mask, intrinsics):
        from posedrift.labelling._forest import PartPrediction

        truth = self.table[hashlib.sha1(np.ascontiguousarray(depth).tobytes()).hexdigest()]
        truth = truth.astype(np.int64) - 1
        valid = (depth > 0) & (truth >= 0) & mask
        rows, cols = np.nonzero(valid)
        prob = np.zeros((len(rows), 15), np.float32)
        prob[np.arange(len(rows)), truth[rows, cols]] = 1.0
        labels = np.full(depth.shape, -1, np.int16)
        labels[rows, cols] = truth[rows, cols]
        pixels = np.column_stack([rows, cols]).astype(np.intp)
        return PartPrediction(labels=labels, pixels=pixels, probabilities=prob)


def test_eval_synthetic_cli_schema_and_skip(mocap_dir, tmp_path, monkeypatch):
    import posedrift.synthetic as synthetic

    oracle = OracleForest()
    build = synthetic.build_sequence

    def spy(*args, **kwargs):
        seq = build(*args, **kwargs)
        oracle.add(seq)
        return seq

    monkeypatch.setattr(synthetic, "build_sequence", spy)
    monkeypatch.setattr(harness, "_default_forest", lambda: oracle)
    bad = tmp_path / "bad.bvh"
    bad.write_text("HIERARCHY\nROOT nothing\n")
    out = tmp_path / "r.json"
    result = CliRunner().invoke(
        app,
        ["-q", "eval", "synthetic", str(mocap_dir / "cmu" / "001_01.bvh"), str(bad)]
        + ["--frames", "12", "--methods", "shotton,pda", "--json", str(out)],
    )
    assert result.exit_code == 1, result.output
    data = json.loads(out.read_text())
    assert set(data) == {
        "protocol",
        "convention",
        "frames",
        "sequences",
        "methods",
        "noise",
        "room",
        "camera",
        "distance",
        "camera_height",
        "camera_tilt",
        "in_place",
        "there_and_back",
        "facing",
        "body",
        "skipped",
    }
    assert data["body"] == {"height": None, "girth": 1.0}
    assert data["protocol"] == "synthetic" and data["frames"] == 12
    assert data["sequences"] == ["001_01"]
    assert list(data["methods"]) == ["shotton", "pda"]
    for row in data["methods"].values():
        assert METHOD_KEYS <= set(row)
        assert list(row["angle_error_deg"]) == [*ANGLE_NAMES, "mean"]
        assert row["label_accuracy"] == 1.0 and row["failed_frames"] == 0
        assert row["angle_error_deg"]["mean"] < 12.0
    assert data["skipped"][0]["sequence"] == str(bad) and data["skipped"][0]["reason"]
    assert "| shotton |" in result.stdout and "| pda |" in result.stdout
    assert "paper: its proposed method (CPD)" in result.stdout


def test_eval_utd_cli_subset_and_unknown(utd_dir, tmp_path, monkeypatch):
    monkeypatch.setitem(harness.METHODS, "centroid", ("test only", Centroid))
    monkeypatch.setattr(harness, "_default_forest", lambda: None)
    out = tmp_path / "u.json"
    result = CliRunner().invoke(
        app,
        ["-q", "eval", "utd", str(utd_dir), "--sequences", "a1_s1_t1,a99_s9_t9"]
        + ["--methods", "centroid", "--json", str(out)],
    )
    assert result.exit_code == 1, result.output
    data = json.loads(out.read_text())
    assert data["protocol"] == "utd" and data["sequences"] == ["a1_s1_t1"]
    row = data["methods"]["centroid"]
    assert row["label_accuracy"] is None and row["failed_frames"] == 0
    assert 0 < row["mpjpe_mm"] < 400  # a T-pose at the centroid, against a standing person
    assert data["skipped"] == [
        {"sequence": "a99_s9_t9", "reason": "no such sequence in the folder"}
    ]
    assert "a99_s9_t9" in result.stderr
    # Scored in the Kinect convention by default; the unconverted errors are kept.
    assert data["convention"] == "kinect"
    assert 0 < row["native"]["mpjpe_mm"] < 400 and row["native"]["mpjpe_mm"] != row["mpjpe_mm"]
    assert "kinect convention" in result.stdout


def test_eval_utd_rejects_unknown_convention(utd_dir):
    result = CliRunner().invoke(app, ["eval", "utd", str(utd_dir), "--convention", "vicon"])
    assert result.exit_code != 0
    assert "Unknown --convention 'vicon'" in result.stderr and "kinect" in result.stderr


def test_eval_rejects_unknown_methods(tmp_path):
    result = CliRunner().invoke(app, ["eval", "synthetic", "builtin", "--methods", "magic"])
    assert result.exit_code == 2
    assert "Unknown method(s) ['magic']" in result.stderr


def test_part_net_options_are_checked_before_any_work(tmp_path):
    from posedrift.cli._options import load_part_net
    from posedrift.labelling import BodyPartNet, FacingNets

    args = ["eval", "synthetic", "builtin", "--frames", "2"]
    result = CliRunner().invoke(app, [*args, "--net", "none", "--turned-net", "x.npz"])
    assert result.exit_code == 2 and "--turned-net needs a part net" in result.stderr
    (tmp_path / "bad.npz").write_bytes(b"not a model")
    result = CliRunner().invoke(app, [*args, "--turned-net", str(tmp_path / "bad.npz")])
    assert result.exit_code == 2 and "bad.npz" in result.stderr
    assert load_part_net(None) is None and load_part_net("none", "none") == "none"
    path = BodyPartNet.load_default().save(tmp_path / "net.npz")
    own = load_part_net(str(path))  # a net of one's own serves every view
    assert isinstance(own, BodyPartNet)
    pair = load_part_net(str(path), str(path))
    assert isinstance(pair, FacingNets) and isinstance(pair.turned, BodyPartNet)
    shipped = load_part_net(None, "none")
    assert shipped is BodyPartNet.load_default()
    assert load_part_net(None, str(path)).frontal is BodyPartNet.load_default()


def test_figures_are_written(tmp_path):
    from posedrift.evaluation._figures import crossing_scores

    seq = _toy_sequence(n=14)
    truth = seq.reference.joints[0]
    report = evaluate(
        [seq],
        {"offset": lambda k, forest=None: Offset(truth), "centroid": Centroid},
        progress=False,
        forest=object(),
        figures_dir=tmp_path,
    )
    names = sorted(p.split("/")[-1] for p in report["figures"])
    assert names == [
        "bland_altman.png",
        "fig12_overlays_toy.png",
        "fig6_labels_toy.png",
        "fig9_angles_toy.png",
    ]
    for p in report["figures"]:
        with open(p, "rb") as f:
            assert f.read(8) == b"\x89PNG\r\n\x1a\n"
    # crossing: right hand moved to the person's left of the left hand scores higher
    crossed = truth.copy()
    crossed[[6, 7]] = crossed[[7, 6]]
    scores = crossing_scores(np.stack([truth, crossed]))
    assert scores[1] > scores[0] + 0.5


# --- eval labels: bad frames are named and skipped, the rest still evaluated -----------------


@pytest.fixture
def label_folder(tmp_path):
    """An 8-frame synth folder with frames 2-7 broken in six different ways."""
    import imageio.v3 as iio

    folder = tmp_path / "s3"
    result = CliRunner().invoke(app, ["-q", "synth", "builtin", "--out", str(folder), "-n", "8"])
    assert result.exit_code == 0, result.output
    (folder / "labels" / "000002.png").write_text("x\n")  # not an image (struct.error before)
    (folder / "depth" / "000003.png").write_bytes(b"")  # zero bytes
    (folder / "labels" / "000004.png").unlink()  # missing
    iio.imwrite(folder / "depth" / "000005.png", np.zeros((10, 10), np.uint16))  # wrong size
    iio.imwrite(folder / "depth" / "000006.png", np.zeros((240, 320), np.uint8))  # 8-bit depth
    labels = iio.imread(folder / "labels" / "000007.png")
    labels[0, 0] = 20
    iio.imwrite(folder / "labels" / "000007.png", labels)  # no part 19
    return folder


BAD_FRAMES = {
    "000002.png": "labels/000002.png is not an image file",
    "000003.png": "depth/000003.png is empty (0 bytes)",
    "000004.png": "labels/000004.png is missing",
    "000005.png": "depth/000005.png is 10 x 10 pixels; ground_truth.json says 320 x 240",
    "000006.png": "depth/000006.png is not a 16-bit (millimetres) greyscale PNG: read uint8 "
    "of shape (240, 320)",
    "000007.png": "labels/000007.png holds 20; labels are 0..15",
}


def test_read_label_folder_skips_bad_frames(label_folder):
    from posedrift.labelling._train import read_label_folder

    skipped = []
    frames = list(read_label_folder(label_folder, on_skip=lambda *a: skipped.append(a)))
    assert [name for name, _ in frames] == ["000000.png", "000001.png"]
    assert dict(skipped) == BAD_FRAMES
    assert frames[0][1].labels.dtype == np.uint8 and frames[0][1].depth.shape == (240, 320)
    # Without on_skip: one RuntimeWarning per frame, naming the folder and the frame.
    with pytest.warns(RuntimeWarning) as caught:
        names = [name for name, _ in read_label_folder(label_folder)]
    assert names == ["000000.png", "000001.png"]
    assert [str(w.message) for w in caught] == [
        f"{label_folder}: skipped frame {name}: {why}" for name, why in BAD_FRAMES.items()
    ]


def test_eval_labels_cli_evaluates_the_rest_and_exits_1(label_folder, tmp_path):
    out = tmp_path / "e.json"
    result = CliRunner().invoke(
        app, ["-q", "eval", "labels", str(label_folder), "--json", str(out)]
    )
    assert result.exit_code == 1, result.output
    assert "Traceback" not in result.output
    data = json.loads(out.read_text())
    assert data["frames"] == 2 and 0.5 < data["pixel_accuracy"] <= 1.0
    assert data["skipped"] == [{"frame": n, "reason": r} for n, r in BAD_FRAMES.items()]
    lines = result.stderr.splitlines()
    for name, why in BAD_FRAMES.items():  # each reported once, naming the frame and the file
        assert [line for line in lines if name in line] == [
            f"error: {label_folder}: skipped frame {name}: {why}"
        ]
    assert "over 2 frames (6 skipped)" in result.stdout


def test_eval_labels_cli_every_frame_bad(label_folder, tmp_path):
    for name in ("000000.png", "000001.png"):
        (label_folder / "depth" / name).write_bytes(b"")
    out = tmp_path / "e.json"
    result = CliRunner().invoke(
        app, ["-q", "eval", "labels", str(label_folder), "--json", str(out)]
    )
    assert result.exit_code == 1
    assert "nothing to evaluate: every frame of" in result.stderr
    data = json.loads(out.read_text())
    assert data["frames"] == 0 and data["pixel_accuracy"] is None and len(data["skipped"]) == 8


# --- eval synthetic: sources named once, the missing file said, every method in --help -------

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


def test_eval_synthetic_names_each_skipped_source_once(tmp_path):
    missing = tmp_path / "nosuch.bvh"
    renamed = tmp_path / "renamed.bvh"
    renamed.write_text(UNMAPPABLE_BVH)
    out = tmp_path / "r.json"
    result = CliRunner().invoke(
        app,
        ["-q", "eval", "synthetic", str(missing), str(renamed), "--frames", "3"]
        + ["--methods", "shotton", "--json", str(out)],
    )
    assert result.exit_code == 1, result.output
    lines = [line for line in result.stderr.splitlines() if line.startswith("error: skipped")]
    assert len(lines) == 2
    assert (
        lines[0] == f"error: skipped {missing}: no such file (SOURCE is a BVH file or 'builtin')."
    )
    assert lines[1].startswith(f"error: skipped {renamed}: cannot map the skeleton")
    assert lines[0].count(missing.name) == 1 and lines[1].count(renamed.name) == 1
    # The command line has no rig option: say what to do there instead.
    assert "Pass rig=" not in result.stderr
    assert "Rename the file's joints to the names looked for" in lines[1]
    assert "bvh_motion(path, rig={joint name: node name})" in lines[1]
    assert "nothing to evaluate: every sequence was skipped" in result.stderr
    data = json.loads(out.read_text())
    assert [s["sequence"] for s in data["skipped"]] == [str(missing), str(renamed)]
    assert "no such file" in data["skipped"][0]["reason"]


def test_methods_help_lists_every_method():
    from posedrift.cli._eval import _METHODS_HELP

    named = set(_METHODS_HELP.replace(",", " ").replace(".", " ").split())
    assert set(harness.METHODS) <= named
    for command in ("synthetic", "utd"):
        result = CliRunner().invoke(app, ["eval", command, "--help"], env={"COLUMNS": "300"})
        assert result.exit_code == 0
        assert "cpd-paper" in result.output and "icp-paper" in result.output


# --- eval utd / the harness: unusable sequences named and skipped, the rest evaluated -----------


def _write_utd(root, name, *, frames=3, depth=None, skel=None):
    """Tiny UTD-MHAD files: ``Depth/{name}_depth.mat`` (a 3 m box) and a still skeleton
    (``skel=False``: no skeleton file)."""
    from scipy.io import savemat

    (root / "Depth").mkdir(parents=True, exist_ok=True)
    (root / "Skeleton").mkdir(exist_ok=True)
    if depth is None:
        depth = np.zeros((240, 320, frames), np.uint16)
        depth[60:200, 140:180] = 3000
    savemat(str(root / "Depth" / f"{name}_depth.mat"), {"d_depth": depth}, do_compression=True)
    if skel is None:
        joints = np.random.default_rng(1).normal(scale=0.3, size=(20, 3)) + [0.0, 0.0, 3.0]
        skel = np.repeat(joints[:, :, None], frames, axis=2)
    if skel is not False:
        savemat(str(root / "Skeleton" / f"{name}_skeleton.mat"), {"d_skel": skel})


def _eval_utd(root, *args, monkeypatch):
    monkeypatch.setitem(harness.METHODS, "centroid", ("test only", Centroid))
    monkeypatch.setattr(harness, "_default_forest", lambda: None)
    return CliRunner().invoke(
        app, ["-q", "eval", "utd", str(root), "--methods", "centroid", *map(str, args)]
    )


def _skip_lines(result):
    return [line for line in result.stderr.splitlines() if line.startswith("error: skipped")]


def test_eval_utd_skips_empty_and_untracked_sequences(tmp_path, monkeypatch):
    root = tmp_path / "utd"
    _write_utd(root, "a1_s1_t1")
    _write_utd(root, "a3_s1_t1", depth=np.zeros((240, 320, 0), np.uint16))
    _write_utd(root, "a4_s1_t1", skel=np.zeros((20, 3, 3)))
    _write_utd(root, "a8_s1_t1", skel=np.full((20, 3, 3), np.nan))
    out = tmp_path / "u.json"
    result = _eval_utd(root, "--json", out, monkeypatch=monkeypatch)
    assert result.exit_code == 1, result.output
    assert "Traceback" not in result.output
    data = json.loads(out.read_text())
    assert data["sequences"] == ["a1_s1_t1"] and data["frames"] == 3
    assert data["methods"]["centroid"]["mpjpe_mm"] is not None
    assert [s["sequence"] for s in data["skipped"]] == ["a3_s1_t1", "a4_s1_t1", "a8_s1_t1"]
    assert "a3_s1_t1_depth.mat' holds no frames" in data["skipped"][0]["reason"]
    for item in data["skipped"][1:]:
        assert f"{item['sequence']}_skeleton.mat' has no usable frame" in item["reason"]
    assert len(_skip_lines(result)) == 3
    assert "3 sequence(s) skipped (named above)" in result.stderr
    # Alone, an untracked reference is still named and makes the exit status 1.
    result = _eval_utd(root, "--sequences", "a4_s1_t1", "--json", out, monkeypatch=monkeypatch)
    assert result.exit_code == 1, result.output
    assert _skip_lines(result)[0].startswith("error: skipped a4_s1_t1: The UTD-MHAD skeleton")
    assert "nothing to evaluate" in result.stderr
    assert json.loads(out.read_text())["skipped"][0]["sequence"] == "a4_s1_t1"


def test_run_methods_skips_unusable_sequences():
    good = _toy_sequence(name="good")
    k = good.frames[0].intrinsics
    nothing = Reference(joints=np.zeros((0, 15, 3)), angles=np.zeros((0, 8)))
    empty = EvaluationSequence(name="empty", frames=(), reference=nothing)
    joints = np.full((2, 15, 3), np.nan)
    untracked = EvaluationSequence(
        name="untracked",
        frames=tuple(DepthFrame(np.zeros(k.shape, np.float32), k, index=t) for t in range(2)),
        reference=Reference(joints=joints, angles=joint_angles(joints)),
    )
    again = _toy_sequence(n=3, name="good")
    skipped = []
    run = harness.run_methods(
        [empty, good, untracked, again],
        {"centroid": Centroid},
        forest=object(),
        progress=False,
        on_skip=lambda *a: skipped.append(a),
    )
    assert [s.name for s in run.sequences] == ["good"] and len(run.runs) == 1
    assert len(run.runs[("centroid", "good")].results) == 6  # the first "good", not the second
    assert skipped == run.skipped
    assert skipped == [
        ("empty", "it has no frames"),
        (
            "untracked",
            "its reference has no usable frame (in none of its 2 frames are all 15 joints finite)",
        ),
        ("good", "a sequence of the same name was already evaluated in this run"),
    ]
    # Without on_skip: a warning per sequence; nothing usable at all is an error.
    with pytest.warns(RuntimeWarning, match="skipped sequence 'empty': it has no frames"):
        with pytest.raises(ValueError, match=r"No sequence to evaluate \(1 skipped\)"):
            harness.run_methods([empty], {"centroid": Centroid}, forest=object(), progress=False)


def test_eval_utd_odd_names_repeats_limit_and_empty_list(tmp_path, monkeypatch):
    root = tmp_path / "utd"
    _write_utd(root, "a1_s1_t1")
    _write_utd(root, "a2_s1_t1", skel=False)
    _write_utd(root, "a5_s1_t1 (copy)")
    _write_utd(root, "A6_S1_T1")
    out = tmp_path / "u.json"
    result = _eval_utd(root, "--json", out, monkeypatch=monkeypatch)
    assert result.exit_code == 1, result.output  # a2 has no skeleton
    assert json.loads(out.read_text())["sequences"] == ["a1_s1_t1", "A6_S1_T1"]
    warned = [line for line in result.stderr.splitlines() if "a5_s1_t1 (copy)" in line]
    assert len(warned) == 1 and warned[0].startswith("warning: ")
    assert "a5_s1_t1 (copy)_depth.mat: the name does not follow" in warned[0]
    # Asked for by name, the odd file is evaluated; no warning about what was not asked for.
    result = _eval_utd(
        root, "--sequences", "a5_s1_t1 (copy),a6_s1_t1", "--json", out, monkeypatch=monkeypatch
    )
    assert result.exit_code == 0, result.output
    assert json.loads(out.read_text())["sequences"] == ["a5_s1_t1 (copy)", "A6_S1_T1"]
    assert "warning" not in result.stderr
    # A repeated name: evaluated once, said once.
    result = _eval_utd(
        root, "--sequences", "a1_s1_t1,a1_s1_t1,a1_s1_t1", "--json", out, monkeypatch=monkeypatch
    )
    assert result.exit_code == 0, result.output
    data = json.loads(out.read_text())
    assert data["sequences"] == ["a1_s1_t1"] and data["frames"] == 3
    assert result.stderr.count("warning: a1_s1_t1: named more than once") == 1
    # --limit 1: the missing skeleton of a2 (not selected) does not count.
    result = _eval_utd(root, "--limit", "1", "--json", out, monkeypatch=monkeypatch)
    assert result.exit_code == 0, result.output
    assert json.loads(out.read_text())["skipped"] == [] and not _skip_lines(result)
    result = _eval_utd(root, "--limit", "2", monkeypatch=monkeypatch)
    assert result.exit_code == 1 and _skip_lines(result)[0].startswith("error: skipped a2_s1_t1")
    # An empty --sequences list says so.
    result = _eval_utd(root, "--sequences", ",", monkeypatch=monkeypatch)
    assert result.exit_code == 2
    assert "--sequences ',' names no sequence" in result.stderr
    assert "named above" not in result.stderr


@pytest.mark.data
def test_eval_synthetic_same_stem_gets_distinct_names(mocap_dir, tmp_path, monkeypatch):
    import shutil

    monkeypatch.setitem(harness.METHODS, "centroid", ("test only", Centroid))
    monkeypatch.setattr(harness, "_default_forest", lambda: None)
    for folder, clip in (("d1", "001_01"), ("d2", "001_08")):
        (tmp_path / folder).mkdir()
        shutil.copy(mocap_dir / "cmu" / f"{clip}.bvh", tmp_path / folder / "x.bvh")
    first, second = tmp_path / "d1" / "x.bvh", tmp_path / "d2" / "x.bvh"
    again = tmp_path / "d1" / ".." / "d1" / "x.bvh"
    out = tmp_path / "r.json"
    result = CliRunner().invoke(
        app,
        ["-q", "eval", "synthetic", str(first), str(second), str(again), "--frames", "3"]
        + ["--methods", "centroid", "--json", str(out)],
    )
    assert result.exit_code == 0, result.output
    data = json.loads(out.read_text())
    assert data["sequences"] == ["x", "x-2"] and data["frames"] == 6
    assert list(data["methods"]["centroid"]["per_sequence"]) == ["x", "x-2"]
    assert f"note: {second} is evaluated as 'x-2' ({first} is 'x')" in result.stderr
    assert f"warning: {again} is given more than once (as {first}): evaluated once" in (
        result.stderr
    )


def test_eval_synthetic_renders_the_body_asked_for(tmp_path, monkeypatch):
    import posedrift.synthetic as synthetic

    oracle = OracleForest()
    build = synthetic.build_sequence
    built = []

    def spy(*args, **kwargs):
        seq = build(*args, **kwargs)
        oracle.add(seq)
        built.append(seq)
        return seq

    monkeypatch.setattr(synthetic, "build_sequence", spy)
    monkeypatch.setattr(harness, "_default_forest", lambda: oracle)
    out = tmp_path / "b.json"
    args = ["-q", "eval", "synthetic", "builtin", "--frames", "3", "--methods", "pda"]
    result = CliRunner().invoke(
        app, [*args, "--height", "1.55", "--girth", "1.2", "--json", str(out)]
    )
    assert result.exit_code == 0, result.output
    assert json.loads(out.read_text())["body"] == {"height": 1.55, "girth": 1.2}
    # The stature is the posed body's at frame 0 (the T-pose): against a 1.75 m one, the
    # skeleton's head-to-ankle span scales with it.
    assert CliRunner().invoke(app, [*args, "--height", "1.75"]).exit_code == 0
    head = JOINT_NAMES.index("head")
    feet = [JOINT_NAMES.index("right_foot"), JOINT_NAMES.index("left_foot")]
    short, tall = (b.reference.joints[0] for b in built)
    spans = [j[feet, 1].mean() - j[head, 1] for j in (short, tall)]  # camera +Y is down
    assert abs(spans[0] / spans[1] - 1.55 / 1.75) < 0.005
    for bad, option in ((["--height", "3"], "--height"), (["--girth", "0"], "--girth")):
        result = CliRunner().invoke(app, [*args, *bad])
        assert result.exit_code == 2 and option in result.output


@pytest.fixture
def built(monkeypatch):
    """The sequences ``eval synthetic`` builds, in order, kept for the test to look at."""
    import posedrift.synthetic as synthetic

    build = synthetic.build_sequence
    sequences = []

    def spy(*args, **kwargs):
        sequences.append(build(*args, **kwargs))
        return sequences[-1]

    monkeypatch.setattr(synthetic, "build_sequence", spy)
    return sequences


def test_eval_synthetic_in_a_room_with_another_camera(tmp_path, built):
    out = tmp_path / "room.json"
    args = ["-q", "eval", "synthetic", "builtin", "--frames", "4", "--methods", "cpd,shotton"]
    camera = ["--camera", "d435", "--distance", "2.0"]
    result = CliRunner().invoke(app, [*args, "--room", *camera, "--json", str(out)])
    assert result.exit_code == 0, result.output
    data = json.loads(out.read_text())
    assert data["room"] is True and data["noise"] is False
    assert data["camera"] == "d435" and data["distance"] == 2.0
    frame, truth = built[0].frames[1], built[0].reference.labels[1]
    assert frame.depth.shape == (480, 640)
    pelvis_depth = built[0].reference.joints[0, JOINT_NAMES.index("torso"), 2]
    assert abs(pelvis_depth - 2.0) < 0.15
    assert (frame.depth[truth == 0] > 0).mean() > 0.5  # floor and wall fill the background
    for row in data["methods"].values():  # both methods found the person in the room
        assert row["failed_frames"] == 0 and row["mpjpe_mm"] < 100
    for bad, option in (
        (["--camera", "pinhole9"], "--camera"),
        (["--distance", "0"], "--distance"),
    ):
        result = CliRunner().invoke(app, [*args, *bad])
        assert result.exit_code == 2 and option in result.output


def test_eval_synthetic_turns_the_person_away(tmp_path, built):
    out = tmp_path / "back.json"
    args = ["-q", "eval", "synthetic", "builtin", "--frames", "2", "--methods", "pda"]
    result = CliRunner().invoke(app, [*args, "--facing", "180", "--json", str(out)])
    assert result.exit_code == 0, result.output
    assert json.loads(out.read_text())["facing"] == 180.0
    assert abs(facing_yaw(built[0].reference.joints[0]) - 180.0) < 1.0
    result = CliRunner().invoke(app, [*args, "--facing", "400"])
    assert result.exit_code == 2 and "--facing" in result.output


def test_eval_synthetic_looks_down_from_a_high_camera(tmp_path, built):
    out = tmp_path / "high.json"
    args = ["-q", "eval", "synthetic", "builtin", "--frames", "2", "--methods", "pda"]
    high = ["--camera-height", "2.2", "--camera-tilt", "25"]
    result = CliRunner().invoke(app, [*args, *high, "--json", str(out)])
    assert result.exit_code == 0, result.output
    data = json.loads(out.read_text())
    assert data["camera_height"] == 2.2 and data["camera_tilt"] == 25.0
    # The person's vertical leans 25 degrees in the camera frame: head nearer than feet.
    joints = built[0].reference.joints[0]
    head, foot = joints[JOINT_NAMES.index("head")], joints[JOINT_NAMES.index("right_foot")]
    lean = np.degrees(np.arctan2(foot[2] - head[2], foot[1] - head[1]))
    assert abs(lean - 25.0) < 3.0
    for bad in (["--camera-tilt", "90"], ["--camera-height", "0"]):
        result = CliRunner().invoke(app, [*args, *bad])
        assert result.exit_code == 2 and bad[0] in result.output


# --- repeats: the trackers run with several point-sampling seeds ------------------------------


class Shifted(Centroid):
    """Test-only seeded method: the centroid T-pose moved ``rng`` centimetres to the right."""

    def __init__(self, intrinsics, *, forest=None, rng=0):
        super().__init__(intrinsics)
        self.shift = 0.01 * rng

    def process(self, frame):
        result = super().process(frame)
        return FrameResult(
            frame.index, result.status, result.joints + [self.shift, 0, 0], result.confidence
        )


def _seeded(cls):
    def factory(intrinsics, *, forest=None, rng=0):
        return cls(intrinsics, forest=forest, rng=rng)

    factory.seeded = True
    return factory


def test_repeats_average_the_seeded_methods_over_their_seeds():
    seq = _toy_sequence()
    methods = {"shifted": _seeded(Shifted), "centroid": Centroid}
    report = evaluate([seq], methods, progress=False, forest=object(), repeats=3)
    assert report["repeats"] == 3
    # Each seed alone, as run_methods runs it: the mean row is their mean, number by number.
    alone = [
        harness.summarize(
            harness.run_methods([seq], methods, progress=False, forest=object(), seed=k)
        )
        for k in range(3)
    ]
    row = report["methods"]["shifted"]
    mpjpe = [a["methods"]["shifted"]["mpjpe_mm"] for a in alone]
    assert len(set(mpjpe)) == 3  # each seed shifts the skeleton another centimetre
    assert row["mpjpe_mm"] == pytest.approx(np.mean(mpjpe), abs=0.01)
    assert row["repeats"]["seeds"] == [0, 1, 2]
    # A shift moves no angle: the same error for every seed, no spread.
    angles = [a["methods"]["shifted"]["angle_error_deg"]["mean"] for a in alone]
    assert row["repeats"]["angle_error_mean_deg"] == pytest.approx(angles)
    assert row["repeats"]["sd_deg"] == pytest.approx(0.0, abs=1e-9)
    assert row["failed_frames"] == 0 and row["status_counts"]["tracked"] == 6
    # The unseeded method runs once: its row is the first run's, without a repeats block.
    once, first = report["methods"]["centroid"], alone[0]["methods"]["centroid"]
    assert "repeats" not in once
    assert {k: v for k, v in once.items() if k != "frames_per_second"} == {
        k: v for k, v in first.items() if k != "frames_per_second"
    }
    single = evaluate([seq], methods, progress=False, forest=object())
    assert "repeats" not in single and "repeats" not in single["methods"]["shifted"]
    assert single["methods"]["shifted"]["mpjpe_mm"] == mpjpe[0]
    with pytest.raises(ValueError, match="'repeats' parameter of evaluate"):
        evaluate([seq], methods, progress=False, forest=object(), repeats=0)


def test_repeats_reseed_the_tracker(tmp_path):
    """The trackers' factories pass the seed on: other point samples, other errors."""
    result = CliRunner().invoke(
        app,
        [
            "eval", "synthetic", "builtin", "--frames", "12", "--methods", "cpd,shotton",
            "--repeats", "2", "--json", str(tmp_path / "r.json"), "--no-paper",
        ],
    )  # fmt: skip
    assert result.exit_code == 0, result.output
    report = json.loads((tmp_path / "r.json").read_text())
    spread = report["methods"]["cpd"]["repeats"]
    assert spread["seeds"] == [0, 1]
    first, second = spread["angle_error_mean_deg"]
    assert first != second
    assert report["methods"]["cpd"]["angle_error_deg"]["mean"] == pytest.approx(
        (first + second) / 2, abs=1e-3
    )
    assert "repeats" not in report["methods"]["shotton"]
    cpd_row = next(line for line in result.output.splitlines() if line.startswith("| cpd"))
    assert f"± {spread['sd_deg']:.2f}" in cpd_row
    bad = CliRunner().invoke(app, ["eval", "synthetic", "builtin", "--repeats", "0"])
    assert bad.exit_code == 2 and "--repeats" in bad.output
