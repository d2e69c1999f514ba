"""The body-part forest: sklearn export, inference, the model file and its validation."""

from __future__ import annotations

import io
import json
import zipfile
from pathlib import Path

import numpy as np
import pytest

from posedrift.camera import Intrinsics, camera_preset
from posedrift.labelling import BodyPartForest, depth_features
from posedrift.labelling._forest import FORMAT_VERSION
from posedrift.labelling._train import (
    LabelledFrame,
    label_accuracy,
    offset_bank,
    sample_pixels,
    train_forest,
)
from posedrift.skeleton import PART_NAMES

CAM = camera_preset("kinect1-qvga")

# A blocky figure: (part, x0, x1, y0, y1, dz), metres; x < 0 is the person's right,
# which a camera facing the person shows on the image's left.
_BOXES = [
    (0, -0.09, 0.09, 0.00, 0.23, 0.00),
    (1, -0.18, 0.18, 0.23, 0.55, 0.00),
    (2, -0.16, 0.16, 0.55, 0.85, 0.02),
    (3, -0.30, -0.18, 0.25, 0.55, -0.03),
    (4, 0.18, 0.30, 0.25, 0.55, -0.03),
    (5, -0.32, -0.20, 0.55, 0.80, -0.08),
    (6, 0.20, 0.32, 0.55, 0.80, -0.08),
    (7, -0.33, -0.21, 0.80, 0.95, -0.12),
    (8, 0.21, 0.33, 0.80, 0.95, -0.12),
    (9, -0.15, -0.01, 0.85, 1.25, 0.00),
    (10, 0.01, 0.15, 0.85, 1.25, 0.00),
    (11, -0.14, -0.02, 1.25, 1.65, 0.02),
    (12, 0.02, 0.14, 1.25, 1.65, 0.02),
    (13, -0.16, -0.02, 1.65, 1.72, -0.05),
    (14, 0.02, 0.16, 1.65, 1.72, -0.05),
]


def toy_frame(rng: np.random.Generator, cam: Intrinsics = CAM) -> LabelledFrame:
    """A 15-part box figure at a random place and distance."""
    distance = rng.uniform(2.4, 3.2)
    depth = np.zeros(cam.shape, np.float32)
    labels = np.zeros(cam.shape, np.uint8)
    s = cam.fx / distance
    cx = cam.cx + rng.uniform(-30, 30)
    top = cam.cy - 0.9 * s + rng.uniform(-10, 10)
    for part, x0, x1, y0, y1, dz in _BOXES:
        r0, r1 = int(top + y0 * s), int(top + y1 * s)
        c0, c1 = int(cx + x0 * s), int(cx + x1 * s)
        depth[r0:r1, c0:c1] = distance + dz
        labels[r0:r1, c0:c1] = part + 1
    return LabelledFrame(depth, labels, cam)


@pytest.fixture(scope="module")
def toy_forest() -> BodyPartForest:
    rng = np.random.default_rng(0)
    frames = [toy_frame(rng) for _ in range(12)]
    return train_forest(
        iter(frames),
        n_frames=12,
        n_offsets=120,
        pixels_per_frame=600,
        max_depth=12,
        min_samples_leaf=2,
        n_jobs=1,
        rng=1,
    )


def _random_problem(seed: int = 0):
    rng = np.random.default_rng(seed)
    x = np.round(rng.normal(size=(3000, 30)), 2).astype(np.float32)
    y = (np.abs(5 * x[:, 0] + 3 * x[:, 1]).astype(int)) % 15
    x_test = np.round(rng.normal(size=(2000, 30)), 2).astype(np.float32)
    return x, y, x_test, rng.normal(size=(30, 4))


@pytest.mark.parametrize("kind", ["RandomForestClassifier", "ExtraTreesClassifier"])
def test_export_reproduces_sklearn_exactly(kind):
    ensemble = pytest.importorskip("sklearn.ensemble")
    x, y, x_test, offsets = _random_problem()
    est = getattr(ensemble, kind)(n_estimators=3, max_depth=15, random_state=0).fit(x, y)
    forest = BodyPartForest.from_sklearn(est, offsets)
    # Same leaf for every sample in every tree, and the same probabilities.
    leaves = forest.apply_features(x_test) - forest.roots[None, :]
    np.testing.assert_array_equal(leaves, est.apply(x_test))
    np.testing.assert_allclose(
        forest.predict_proba_features(x_test), est.predict_proba(x_test), atol=1e-6
    )


def test_export_maps_missing_classes_to_their_parts():
    tree = pytest.importorskip("sklearn.tree")
    x, y, x_test, offsets = _random_problem(1)
    y = np.where(y % 2 == 0, 4, 11)  # only two parts present
    est = tree.DecisionTreeClassifier(max_depth=6, random_state=0).fit(x, y)
    proba = BodyPartForest.from_sklearn(est, offsets).predict_proba_features(x_test)
    assert proba.shape == (2000, 15)
    np.testing.assert_allclose(proba[:, [4, 11]], est.predict_proba(x_test), atol=1e-6)
    assert proba[:, [i for i in range(15) if i not in (4, 11)]].max() == 0.0


def test_frame_prediction_equals_the_feature_matrix_path(toy_forest):
    frame = toy_frame(np.random.default_rng(5))
    pred = toy_forest.predict(frame.depth, frame.mask, frame.intrinsics)
    x = depth_features(
        frame.depth, pred.pixels, toy_forest.offsets, intrinsics=CAM, mask=frame.mask
    )
    np.testing.assert_array_equal(pred.probabilities, toy_forest.predict_proba_features(x))
    assert pred.labels.dtype == np.int16 and pred.labels.shape == CAM.shape
    assert (pred.labels[~frame.mask] == -1).all()
    np.testing.assert_array_equal(
        pred.labels[pred.pixels[:, 0], pred.pixels[:, 1]], pred.probabilities.argmax(axis=1)
    )
    np.testing.assert_allclose(pred.probabilities.sum(axis=1), 1.0, atol=1e-5)


def test_toy_forest_learns_the_parts(toy_forest):
    rng = np.random.default_rng(7)
    test = [toy_frame(rng) for _ in range(3)]
    accuracy, correct, total = label_accuracy(toy_forest, test)
    assert accuracy > 0.9
    # Left and right are not swapped: each side's hand is mostly right.
    assert correct[PART_NAMES.index("left_hand")] / total[PART_NAMES.index("left_hand")] > 0.7
    assert correct[PART_NAMES.index("right_hand")] / total[PART_NAMES.index("right_hand")] > 0.7


def test_offsets_scale_to_another_camera(toy_forest):
    # The same scene at twice the resolution: labels agree with the QVGA ones.
    vga = CAM.scaled(2.0)
    frame = toy_frame(np.random.default_rng(11))
    big = LabelledFrame(
        np.repeat(np.repeat(frame.depth, 2, 0), 2, 1),
        np.repeat(np.repeat(frame.labels, 2, 0), 2, 1),
        vga,
    )
    accuracy, _, _ = label_accuracy(toy_forest, [big])
    assert accuracy > 0.85


def test_empty_mask_gives_an_empty_map(toy_forest):
    pred = toy_forest.predict(np.zeros(CAM.shape), None, CAM)
    assert (pred.labels == -1).all() and pred.pixels.shape == (0, 2)
    assert pred.probabilities.shape == (0, 15)
    frame = toy_frame(np.random.default_rng(2))
    pred = toy_forest.predict(frame.depth, np.zeros(CAM.shape, bool), CAM)
    assert (pred.labels == -1).all()


def test_predict_rejects_bad_arguments(toy_forest):
    with pytest.raises(ValueError, match="'depth'.*shape"):
        toy_forest.predict(np.zeros((10, 10)), None, CAM)
    with pytest.raises(ValueError, match="'mask'"):
        toy_forest.predict(np.zeros(CAM.shape), np.zeros((3, 3), bool), CAM)
    with pytest.raises(ValueError, match="'intrinsics'"):
        toy_forest.predict(np.zeros(CAM.shape), None, "kinect")


def test_save_load_round_trip(toy_forest, tmp_path):
    path = toy_forest.save(tmp_path / "forest.npz")
    loaded = BodyPartForest.load(path)
    for name in ("offsets", "roots", "feature", "threshold", "left", "right", "leaf"):
        np.testing.assert_array_equal(getattr(loaded, name), getattr(toy_forest, name))
    np.testing.assert_allclose(loaded.leaf_values, toy_forest.leaf_values, atol=1e-3)
    assert loaded.metadata == json.loads(json.dumps(dict(toy_forest.metadata)))
    frame = toy_frame(np.random.default_rng(3))
    a = toy_forest.predict(frame.depth, frame.mask, CAM)
    b = loaded.predict(frame.depth, frame.mask, CAM)
    assert np.mean(a.labels == b.labels) > 0.999


def _rewrite(src: Path, dst: Path, **changes) -> Path:
    with np.load(src, allow_pickle=False) as npz:
        arrays = {k: npz[k] for k in npz.files}
    arrays.update(changes)
    for key in [k for k, v in changes.items() if v is None]:
        del arrays[key]
    with open(dst, "wb") as handle:
        np.savez(handle, **arrays)
    return dst


def test_bad_model_files_are_rejected(toy_forest, tmp_path):
    good = toy_forest.save(tmp_path / "good.npz")
    with np.load(good, allow_pickle=False) as npz:
        left, feature, leaf = npz["left"].copy(), npz["feature"].copy(), npz["leaf"].copy()
    internal = np.flatnonzero(feature >= 0)
    cases = {
        "version": (dict(version=np.array(FORMAT_VERSION + 1, np.int32)), "format version 2"),
        "format": (dict(format=np.array("something-else")), "not a posedrift forest"),
        "missing": (dict(threshold=None), "missing"),
        "child": (dict(left=_set(left, internal[0], 10**6)), "child indices"),
        "cycle": (dict(left=_set(left, internal[-1], 0)), "child indices"),
        "feature": (dict(feature=_set(feature, internal[0], 10**5)), "'feature' ids"),
        "leaf": (dict(leaf=_set(leaf, int(np.flatnonzero(leaf >= 0)[0]), 10**7)), "'leaf'"),
        "dtype": (dict(threshold=np.zeros(len(feature), np.int32)), "'threshold'"),
        "nan": (dict(offsets=np.full((len(toy_forest.offsets), 4), np.nan, np.float32)), "finite"),
    }
    for name, (change, match) in cases.items():
        path = _rewrite(good, tmp_path / f"{name}.npz", **change)
        with pytest.raises(ValueError, match=match):
            BodyPartForest.load(path)


def _set(array: np.ndarray, index: int, value: int) -> np.ndarray:
    out = array.copy()
    out[index] = value
    return out


def test_truncated_and_pickled_files_are_rejected(toy_forest, tmp_path):
    good = toy_forest.save(tmp_path / "good.npz")
    data = good.read_bytes()
    truncated = tmp_path / "truncated.npz"
    truncated.write_bytes(data[: len(data) // 2])
    with pytest.raises(ValueError, match="truncated or corrupt"):
        BodyPartForest.load(truncated)
    not_zip = tmp_path / "text.npz"
    not_zip.write_text("hello")
    with pytest.raises(ValueError, match=r"text\.npz"):
        BodyPartForest.load(not_zip)
    with pytest.raises(ValueError, match="Cannot read"):
        BodyPartForest.load(tmp_path / "absent.npz")
    npy = tmp_path / "array.npy"
    np.save(npy, np.arange(3))
    with pytest.raises(ValueError, match="not an .npz archive"):
        BodyPartForest.load(npy)
    # An object array (a pickle inside the .npy) is never unpickled.
    with np.load(good, allow_pickle=False) as npz:
        arrays = {k: npz[k] for k in npz.files}
    arrays["metadata"] = np.array([{"evil": print}], dtype=object)
    buffer = io.BytesIO()
    np.savez(buffer, **arrays)
    pickled = tmp_path / "pickled.npz"
    pickled.write_bytes(buffer.getvalue())
    with zipfile.ZipFile(pickled) as zf:
        assert "metadata.npy" in zf.namelist()
    with pytest.raises(ValueError, match="cannot be read safely"):
        BodyPartForest.load(pickled)


def test_offset_bank_and_pixel_sampling_are_seeded():
    a = offset_bank(50, rng=3)
    np.testing.assert_array_equal(a, offset_bank(50, rng=3))
    assert a.shape == (50, 4) and np.abs(a).max() <= 1.3 * 285.63 + 1e-3
    assert np.mean(np.all(a[:, 2:] == 0, axis=1)) > 0.05
    frame = toy_frame(np.random.default_rng(0))
    p = sample_pixels(frame.labels, frame.mask, 500, balance=1.0, rng=0)
    np.testing.assert_array_equal(
        p, sample_pixels(frame.labels, frame.mask, 500, balance=1.0, rng=0)
    )
    assert frame.mask[p[:, 0], p[:, 1]].all() and len(np.unique(p, axis=0)) == 500
    # Balanced sampling: the hands are drawn far more often than their pixel share.
    counts = np.bincount(frame.labels[p[:, 0], p[:, 1]], minlength=16)[1:]
    assert counts.min() >= 500 / 15 * 0.5


def held_out_frames(
    mocap_dir, views, *, camera_height: float = 1.0, aim_at_body: bool = False
) -> list[LabelledFrame]:
    """Fresh renders of 007_01 (kept out of the shipped models' training), one per
    ``(frame, yaw)`` of ``views``, the frame at 90 with Kinect-like noise; the camera
    level at ``camera_height`` or (``aim_at_body``) aimed at the pelvis from there."""
    from posedrift.labelling._train import render_training_frame
    from posedrift.synthetic import BodyModel, bvh_motion

    motion = bvh_motion(mocap_dir / "cmu" / "007_01.bvh")
    body = BodyModel.load_default().with_shape(height=1.68, girth=1.1)
    rng = np.random.default_rng(0)
    frames = []
    for t, yaw in views:
        joints = np.asarray(motion.joints[t], dtype=float)
        scale = 1.68 / _stature_of(motion)
        origin = np.array([joints[:, 0].mean(), 0.0, joints[:, 2].mean()])
        extras = {k: origin + (np.asarray(v[t]) - origin) * scale for k, v in motion.extras.items()}
        frames.append(
            render_training_frame(
                origin + (joints - origin) * scale,
                extras,
                body,
                CAM,
                yaw=yaw,
                distance=2.8,
                camera_height=camera_height,
                aim_at_body=aim_at_body,
                noise=t == 90,
                rng=rng,
            )
        )
    return frames


def test_default_model_labels_a_held_out_clip(mocap_dir):
    """The shipped model on three fresh frames of a clip kept out of its training."""
    forest = BodyPartForest.load_default()
    assert forest.metadata["excluded"] and "007_01.bvh" not in forest.metadata["clips"]
    frames = held_out_frames(mocap_dir, ((30, 0.0), (90, 25.0), (140, -30.0)))
    accuracy, correct, total = label_accuracy(forest, frames)
    assert accuracy >= 0.75
    for side in ("left", "right"):
        for part in ("upper_arm", "thigh"):
            i = PART_NAMES.index(f"{side}_{part}")
            assert correct[i] / total[i] > 0.5, (side, part)


def _stature_of(motion) -> float:
    from posedrift.labelling._train import _stature

    return _stature(np.asarray(motion.joints[0], dtype=float))


def _write_synth_folder(folder: Path, frames: list[LabelledFrame]) -> Path:
    import imageio.v3 as iio

    (folder / "depth").mkdir(parents=True)
    (folder / "labels").mkdir()
    for i, frame in enumerate(frames):
        mm = np.rint(frame.depth * 1000).astype(np.uint16)
        iio.imwrite(folder / "depth" / f"{i:06d}.png", mm)
        iio.imwrite(folder / "labels" / f"{i:06d}.png", frame.labels)
    truth = {"intrinsics": CAM.to_dict(), "fps": 30.0, "frames": []}
    (folder / "ground_truth.json").write_text(json.dumps(truth))
    return folder


def test_cli_eval_labels_writes_json_and_picture(toy_forest, tmp_path):
    from typer.testing import CliRunner

    from posedrift.cli import app

    rng = np.random.default_rng(21)
    folder = _write_synth_folder(tmp_path / "synth", [toy_frame(rng) for _ in range(3)])
    model = toy_forest.save(tmp_path / "toy.npz")
    out = tmp_path / "labels.json"
    result = CliRunner().invoke(
        app, ["-q", "eval", "labels", str(folder), "--json", str(out), "--model", str(model)]
    )
    assert result.exit_code == 0, result.output
    data = json.loads(out.read_text())
    assert {"pixel_accuracy", "per_part", "frames", "ms_per_frame"} <= set(data)
    assert sum(band["frames"] for band in data["by_distance"].values()) == 3
    assert data["frames"] == 3 and data["pixel_accuracy"] > 0.9
    assert list(data["per_part"]) == list(PART_NAMES) and data["ms_per_frame"] > 0
    assert (tmp_path / "labels.png").stat().st_size > 1000
    # A corrupt model and a folder that is not a synth folder: clear errors, exit code 2.
    bad = tmp_path / "bad.npz"
    bad.write_bytes(model.read_bytes()[:100])
    result = CliRunner().invoke(
        app, ["eval", "labels", str(folder), "--json", str(out), "--model", str(bad)]
    )
    assert result.exit_code == 2 and "truncated or corrupt" in result.output
    result = CliRunner().invoke(
        app, ["eval", "labels", str(tmp_path), "--json", str(out), "--model", str(model)]
    )
    assert result.exit_code == 2 and "ground_truth.json" in result.output


def test_cli_train_is_reproducible(tmp_path):
    pytest.importorskip("sklearn")
    from typer.testing import CliRunner

    from posedrift.cli import app

    empty = tmp_path / "no_clips"
    empty.mkdir()
    args = ["-q", "train", "--frames", "3", "--pixels", "200", "--offsets", "40"]
    args += ["--depth", "8", "--mocap", str(empty), "--jobs", "1", "--vote-frames", "4"]
    for name in ("a.npz", "b.npz"):
        result = CliRunner().invoke(app, [*args, "--out", str(tmp_path / name)])
        assert result.exit_code == 0, result.output
    a, b = BodyPartForest.load(tmp_path / "a.npz"), BodyPartForest.load(tmp_path / "b.npz")
    np.testing.assert_array_equal(a.threshold, b.threshold)
    np.testing.assert_array_equal(a.offsets, b.offsets)
    np.testing.assert_array_equal(a.votes.offset, b.votes.offset)
    assert a.metadata["vote_frames"] == 4 and (a.votes.weight > 0).any()
    # Without votes: the same trees (the votes draw from their own random stream).
    result = CliRunner().invoke(
        app, [*args, "--vote-frames", "0", "--out", str(tmp_path / "bare.npz")]
    )
    bare = BodyPartForest.load(tmp_path / "bare.npz")
    assert bare.votes is None
    np.testing.assert_array_equal(bare.threshold, a.threshold)
    assert a.metadata["procedural_share"] == 1.0 and a.metadata["seed"] == 0
    assert a.metadata["wide_share"] == 0.3 and a.metadata["wide_yaw"] == 100.0
    assert "no BVH clip to train on" in result.output
    result = CliRunner().invoke(app, [*args, "--out", str(tmp_path / "c.npz"), "--wide-yaw", "200"])
    assert result.exit_code == 2 and "--wide-yaw" in result.output


def test_training_frames_are_seeded_and_show_a_person():
    from posedrift.labelling._train import SceneRanges, synthetic_training_frames
    from posedrift.synthetic import procedural_motion

    motion = procedural_motion(seconds=2.0)
    ranges = SceneRanges(wide_fraction=0.0)
    a = list(synthetic_training_frames(3, [motion], ranges=ranges, rng=4))
    b = list(synthetic_training_frames(3, [motion], ranges=ranges, rng=4))
    for x, y in zip(a, b, strict=True):
        np.testing.assert_array_equal(x.depth, y.depth)
        np.testing.assert_array_equal(x.labels, y.labels)
        assert np.count_nonzero(x.mask) >= 300
        # Distances 2-3.5 m: the person's median depth lies in that range (+- body depth).
        assert 1.8 < np.median(x.depth[x.mask]) < 3.8
    with pytest.raises(ValueError, match="'weights'"):
        next(synthetic_training_frames(1, [motion], weights=[0.0], rng=0))


def test_wide_views_turn_between_their_smallest_and_largest_yaw():
    from posedrift.labelling._train import SceneRanges

    u = np.linspace(-1.0, 1.0, 201)
    default = SceneRanges()
    # Without a smallest turn the draw is what it always was (the shipped models' views).
    assert [default.view_yaw(x, True) for x in u] == list(u * 100.0)
    assert [default.view_yaw(x, False) for x in u] == list(u * 45.0)
    behind = SceneRanges(wide_yaw=180.0, wide_min_yaw=120.0)
    yaws = np.array([behind.view_yaw(x, True) for x in u if x != 0.0])
    assert np.all(np.abs(yaws) >= 120.0) and np.all(np.abs(yaws) <= 180.0)
    assert np.all(np.sign(yaws) == np.sign(u[u != 0.0]))  # either way round
    assert behind.view_yaw(1.0, True) == 180.0 and behind.view_yaw(-1e-9, True) < -119.99
    assert behind.view_yaw(0.5, False) == 22.5  # the frontal views keep their range
    # One side: the same draws' turns, every one showing the left side (positive).
    left = SceneRanges(wide_yaw=165.0, wide_min_yaw=30.0, wide_left_side=True)
    both = SceneRanges(wide_yaw=165.0, wide_min_yaw=30.0)
    assert [left.view_yaw(x, True) for x in u] == [abs(both.view_yaw(x, True)) for x in u]
    assert left.view_yaw(-0.5, False) == -22.5
    with pytest.raises(ValueError, match="'wide_min_yaw' of SceneRanges"):
        SceneRanges(wide_yaw=90.0, wide_min_yaw=120.0)


def test_mirrored_poses_render_as_mirror_images_with_sides_swapped():
    from posedrift.labelling._train import _facing, mirror_pose, render_training_frame
    from posedrift.synthetic import BodyModel, procedural_motion

    motion = procedural_motion()
    # The script's most asymmetric pose (one arm forward, the other sideways...) among
    # those facing +Z, where a mirror image is not just the person turned the other way.
    frontal = [abs(_facing(j)[0]) < 0.02 for j in motion.joints]
    gap = [
        np.abs(mirror_pose(j, {})[0] - j).max() * f
        for j, f in zip(motion.joints, frontal, strict=True)
    ]
    t = int(np.argmax(gap))
    joints = motion.joints[t]
    extras = {name: v[t] for name, v in motion.extras.items()}
    again, extras_again = mirror_pose(*mirror_pose(joints, extras))
    np.testing.assert_allclose(again, joints, atol=1e-12)  # mirroring twice: the identity
    assert all(np.allclose(extras_again[k], extras[k]) for k in extras)
    body, k = BodyModel.load_default(), camera_preset("kinect1-qvga")
    view = {"yaw": 0.0, "distance": 2.8, "camera_height": 1.0, "aim_at_body": False}
    view |= {"aim": 0.0, "noise": False}
    plain = render_training_frame(joints, extras, body, k, rng=0, **view)
    mirrored = render_training_frame(*mirror_pose(joints, extras), body, k, rng=0, **view)
    # The mirror image is the picture flipped left-right, with each part's side swapped.
    swap = np.arange(len(PART_NAMES) + 1)
    for i, name in enumerate(PART_NAMES):
        for a, b in (("left_", "right_"), ("right_", "left_")):
            if name.startswith(a):
                swap[i + 1] = PART_NAMES.index(b + name[len(a) :]) + 1
    # Column u mirrors to 2 cx - u = 320 - u: flip the columns and shift them by one.
    flipped = np.zeros_like(plain.labels)
    flipped[:, 1:] = swap[plain.labels[:, ::-1]][:, :-1]
    person = (flipped > 0) | (mirrored.labels > 0)
    agree = np.mean(flipped[person] == mirrored.labels[person])
    assert agree > 0.9
    assert np.mean(plain.labels[person] == mirrored.labels[person]) < agree - 0.1


def test_fast_descents_reach_the_same_leaves(toy_forest, monkeypatch):
    """The compiled and the few-pixel (fused) descents equal the plain NumPy one."""
    from posedrift.labelling import _forest
    from posedrift.labelling._features import pixel_terms, probe_image

    rng = np.random.default_rng(11)
    frame = toy_frame(rng)
    pixels = np.argwhere(frame.mask)
    # Probes far off the image and pixels at its border too.
    near_edge = np.array([[0, 0], [CAM.height - 1, CAM.width - 1], [0, CAM.width - 1]])
    depth = frame.depth.copy()
    depth[tuple(near_edge.T)] = 0.5
    mask = frame.mask.copy()
    mask[tuple(near_edge.T)] = True
    chosen = np.vstack([pixels[rng.choice(len(pixels), 300, replace=False)], near_edge])
    compiled = _forest._ckernels
    for forest in (toy_forest, BodyPartForest.load_default()):
        image = probe_image(depth, mask, forest.background)
        for some in (chosen, pixels):
            terms = pixel_terms(depth, some, CAM, forest.reference_focal)
            monkeypatch.setattr(_forest, "_ckernels", None)
            monkeypatch.setattr(_forest, "_FUSED_PAIRS", 0)
            plain = forest._descend_frame(image, depth.shape, terms)
            monkeypatch.undo()
            np.testing.assert_array_equal(forest._descend_fused(image, depth.shape, terms), plain)
            if compiled is not None:
                got = forest._descend_compiled(image, depth.shape, terms)
                np.testing.assert_array_equal(got, plain)
        # predict_pixels gives predict's rows.
        full = forest.predict(depth, mask, CAM)
        rows = {tuple(p): i for i, p in enumerate(full.pixels)}
        got = forest.predict_pixels(depth, chosen, CAM, mask=mask)
        np.testing.assert_array_equal(got, full.probabilities[[rows[tuple(p)] for p in chosen]])
    if compiled is not None:
        forest = BodyPartForest.load_default()
        bad_roots = np.array([forest.n_nodes], dtype=np.int32)
        args = [np.zeros(3, np.float32)] * 4
        with pytest.raises(ValueError, match="inconsistent buffers or roots"):
            compiled.descend(
                forest._table.view(np.int32),
                image,
                *args,
                bad_roots,
                3,
                240,
                320,
                np.empty(3, np.int32),
            )


def test_diverse_frames_drop_near_duplicate_poses():
    from posedrift.labelling._train import diverse_frames, pose_descriptors
    from posedrift.skeleton import t_pose_joints
    from posedrift.synthetic import Motion, procedural_motion

    # Identity: a still motion is one pose; the same pose turned and moved is too.
    still = np.stack([t_pose_joints(1.75)] * 20)
    turn = np.array([[0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]])  # 90 deg about +Y
    turned = still @ turn.T + [2.0, 0.0, 1.0]
    kept = diverse_frames([Motion(still), Motion(turned)], 0.01)
    assert sum(len(k) for k in kept) == 1

    motion = procedural_motion(seconds=4.0, fps=30.0)
    desc = pose_descriptors(motion.joints, 1.75).reshape(len(motion.joints), -1, 3)
    for d in (0.03, 0.1):
        [frames] = diverse_frames([motion], d, rng=1)
        gap = np.linalg.norm(desc[:, None] - desc[None, frames], axis=-1).max(axis=-1)  # (T, K)
        # Every kept pair differs by more than d at some joint; every dropped pose has a
        # kept one within d at every joint.
        pairs = gap[frames] + np.diag(np.full(len(frames), np.inf))
        assert pairs.min() > d
        assert np.all(gap.min(axis=1) <= d)
    assert len(diverse_frames([motion], 0.1)[0]) < len(diverse_frames([motion], 0.03)[0])
    # At 0 only exact repeats go (the procedural motion holds its T-pose for a while).
    n_distinct = len(np.unique(desc.reshape(len(desc), -1), axis=0))
    assert len(diverse_frames([motion], 0.0)[0]) == n_distinct < len(motion.joints)


def test_training_clips_any_case_a_single_file_and_clear_errors(tmp_path):
    from posedrift.labelling._train import training_clips

    (tmp_path / "sub").mkdir()
    for name in ("sub/A.BVH", "b.bvh", "007_01.bvh", "notes.txt"):
        (tmp_path / name).write_text("HIERARCHY\n")
    found = [p.name for p in training_clips(tmp_path)]
    assert sorted(found) == ["A.BVH", "b.bvh"]  # 007_* is held out
    assert training_clips(tmp_path / "b.bvh") == [tmp_path / "b.bvh"]
    with pytest.raises(ValueError, match="notes.txt' is not a BVH file or a folder"):
        training_clips(tmp_path / "notes.txt")
    with pytest.raises(ValueError, match="nowhere' does not exist"):
        training_clips(tmp_path / "nowhere")
