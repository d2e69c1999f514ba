"""The evaluation harness and ``posedrift eval``: JSON schema, skipping, exit codes."""

import hashlib
import json

import numpy as np
import pytest
from typer.testing import CliRunner

import posedrift.evaluation._harness as harness
from posedrift.camera import DepthFrame, backproject, camera_preset
from posedrift.cli import app
from posedrift.evaluation import EvaluationSequence, Reference, evaluate, parse_methods
from posedrift.skeleton import ANGLE_NAMES, joint_angles, t_pose_joints
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
    # The toy person faces the camera in every frame.
    assert row["by_view"]["front"] == {"frames": 6, "angle_error_mean_deg": 0.0}
    assert row["by_view"]["back"] == {"frames": 0, "angle_error_mean_deg": None}


def test_parse_methods():
    assert parse_methods("cpd, pda,cpd") == ["cpd", "pda"]
    with pytest.raises(ValueError, match="Unknown method\\(s\\) \\['nope'\\]. Valid methods: cpd"):
        parse_methods("cpd,nope")


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
        "in_place",
        "skipped",
    }
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
    assert names == ["fig12_overlays_toy.png", "fig6_labels_toy.png", "fig9_angles_toy.png"]
    for p in report["figures"]:
        with open(p, "rb") as f:
            assert f.read(8) == b"\x89PNG\r\n\x1a\n"
    # crossing: right hand moved to the person's left of the left hand scores higher
    crossed = truth.copy()
    crossed[[6, 7]] = crossed[[7, 6]]
    scores = crossing_scores(np.stack([truth, crossed]))
    assert scores[1] > scores[0] + 0.5
