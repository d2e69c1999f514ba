"""The synthetic evaluation sequence builder and the synthetic folder format."""

from __future__ import annotations

import json

import numpy as np
import pytest

from posedrift.camera import CameraPose, DepthFrame, Intrinsics, camera_preset, project
from posedrift.evaluation import EvaluationSequence
from posedrift.skeleton import (
    ANGLE_NAMES,
    JOINT_INDEX,
    JOINT_NAMES,
    PART_INDEX,
    facing_yaw,
    pelvis_centre,
    t_pose_joints,
)
from posedrift.synthetic import (
    BodyModel,
    Motion,
    build_sequence,
    contact_sheet,
    place_camera,
    read_synthetic,
    write_synthetic,
)

K = camera_preset("kinect1-qvga")
T_POSE_ANGLES = [180.0, 180.0, 90.0, 90.0, 180.0, 180.0, 0.0, 0.0]


@pytest.fixture(scope="module")
def body() -> BodyModel:
    return BodyModel.load_default()


def _arms_down_motion(n: int = 9, fps: float = 30.0, start_t_pose: bool = True) -> Motion:
    """The T-pose with the arms lowering to about 30 degrees over ``n`` frames."""
    base = t_pose_joints(1.75)
    frames = []
    for i, a in enumerate(np.linspace(0.0 if start_t_pose else 40.0, 60.0, n)):
        j = base.copy()
        for side, sign in (("left", 1.0), ("right", -1.0)):
            shoulder = j[JOINT_INDEX[f"{side}_shoulder"]]
            for name in (f"{side}_elbow", f"{side}_hand"):
                r = j[JOINT_INDEX[name]] - shoulder
                length = np.linalg.norm(r)
                ang = np.radians(a)
                j[JOINT_INDEX[name]] = shoulder + length * np.array(
                    [sign * np.cos(ang), -np.sin(ang), 0.0]
                )
        j[:, 2] += 0.01 * i  # a slow step toward the camera
        frames.append(j)
    return Motion(np.stack(frames), {}, fps, "arms-down")


@pytest.fixture(scope="module")
def sequence(body) -> EvaluationSequence:
    return build_sequence(_arms_down_motion(), body=body)


def test_camera_faces_the_person_at_the_protocol_distance(sequence):
    ref = sequence.reference
    pelvis = 0.5 * (
        ref.joints[0, JOINT_INDEX["left_hip"]] + ref.joints[0, JOINT_INDEX["right_hip"]]
    )
    assert pelvis[0] == pytest.approx(0.0, abs=1e-9)
    assert pelvis[2] == pytest.approx(2.8, abs=1e-9)
    # Camera 1.0 m above the floor, +Y down: the hips (0.53 H high) are above the axis.
    assert pelvis[1] == pytest.approx(1.0 - 0.530 * 1.75, abs=1e-9)
    # Facing the camera: the person's left is on the image's right (+X).
    assert (
        ref.joints[0, JOINT_INDEX["left_hand"], 0] > 0 > ref.joints[0, JOINT_INDEX["right_hand"], 0]
    )
    assert sequence.fps == 30.0 and len(sequence.frames) == 9
    frame = sequence.frames[0]
    assert isinstance(frame, DepthFrame) and frame.intrinsics == K
    assert frame.depth.dtype == np.float32 and frame.depth.shape == (240, 320)
    assert sequence.reference.kind == "synthetic"


def test_reference_joints_land_on_their_rendered_parts(sequence):
    ref = sequence.reference
    checks = {"head": "head", "torso": "upper_torso", "left_knee": "left_thigh"}
    for t in (0, len(sequence.frames) - 1):
        uv = np.rint(project(ref.joints[t], K)).astype(int)
        labels = ref.labels[t]
        depth = sequence.frames[t].depth
        for joint, part in checks.items():
            u, v = uv[JOINT_INDEX[joint]]
            window = labels[v - 2 : v + 3, u - 2 : u + 3]
            assert (window == PART_INDEX[part] + 1).any(), (t, joint, np.unique(window))
        # The depth at the torso joint is the body's front surface, a few cm nearer.
        u, v = uv[JOINT_INDEX["torso"]]
        gap = ref.joints[t, JOINT_INDEX["torso"], 2] - depth[v, u]
        assert 0.02 < gap < 0.25
        # Every labelled pixel has a depth (no background requested).
        assert np.array_equal(labels > 0, depth > 0)


def test_angles_are_those_of_the_motion(sequence):
    motion = _arms_down_motion()
    np.testing.assert_allclose(sequence.reference.angles, motion.angles, atol=1e-9)
    np.testing.assert_allclose(sequence.reference.angles[0], T_POSE_ANGLES, atol=1e-6)


def test_clip_is_resampled_and_a_t_pose_blended_in(body):
    # 60 fps, starting with arms at 40 degrees below horizontal: no T-pose.
    motion = _arms_down_motion(n=21, fps=60.0, start_t_pose=False)
    seq = build_sequence(motion, body=body, n_frames=None)
    # 21 frames at 60 fps = 11 at 30 fps, plus one second of blend from a T-pose.
    assert len(seq.frames) == 11 + 30
    np.testing.assert_allclose(seq.reference.angles[0], T_POSE_ANGLES, atol=1.0)
    # The clip's last frame ends the sequence.
    last = motion.angles[-1]
    np.testing.assert_allclose(seq.reference.angles[-1], last, atol=1e-6)
    first5 = build_sequence(motion, body=body, n_frames=5)
    assert len(first5.frames) == 5
    np.testing.assert_allclose(first5.reference.joints, seq.reference.joints[:5])
    assert len(build_sequence(motion, body=body, n_frames=500).frames) == 41


def test_noise_is_seeded_and_labels_follow_the_surviving_depth(body, sequence):
    motion = _arms_down_motion(n=3)
    a = build_sequence(motion, body=body, noise=True, rng=7)
    b = build_sequence(motion, body=body, noise=True, rng=7)
    for fa, fb in zip(a.frames, b.frames, strict=True):
        np.testing.assert_array_equal(fa.depth, fb.depth)
    clean = sequence.frames[0].depth
    noisy = a.frames[0].depth
    person = clean > 0
    lost = person & (noisy == 0)
    assert 0 < lost.sum() < 0.3 * person.sum()
    kept = person & (noisy > 0)
    err = np.abs(noisy[kept] - clean[kept])
    assert 0.002 < np.median(err) < 0.03  # Kinect v1 at 2.8 m: ~1 cm noise, 2.2 cm steps
    assert np.array_equal(a.reference.labels[0] > 0, noisy > 0)


def test_background_adds_floor_and_wall_but_keeps_the_person(body, sequence):
    seq = build_sequence(_arms_down_motion(n=2), body=body, background=True)
    depth, labels = seq.frames[0].depth, seq.reference.labels[0]
    np.testing.assert_array_equal(labels, sequence.reference.labels[0])
    person = labels > 0
    np.testing.assert_array_equal(depth[person], sequence.frames[0].depth[person])
    assert np.all(depth > 0)  # floor below, wall behind: every pixel is measured
    assert np.median(depth[~person]) > 3.5


def test_body_shape_changes_the_silhouette_not_the_truth(body, sequence):
    wide = build_sequence(_arms_down_motion(n=2), body=body, shape={"girth": 1.3})
    assert (wide.reference.labels[0] > 0).sum() > 1.1 * (sequence.reference.labels[0] > 0).sum()
    np.testing.assert_allclose(wide.reference.joints[0], sequence.reference.joints[0])


def test_other_intrinsics_and_distance(body):
    k = Intrinsics(fx=200.0, fy=200.0, cx=80.0, cy=60.0, width=160, height=120)
    seq = build_sequence(_arms_down_motion(n=2), body=body, intrinsics=k, distance=4.0)
    assert seq.frames[0].depth.shape == (120, 160)
    torso = seq.reference.joints[0, JOINT_INDEX["torso"]]
    assert torso[2] == pytest.approx(4.0)
    assert set(np.unique(seq.reference.labels[0])) == set(range(16))


def test_place_camera_looks_level_at_the_pelvis():
    motion = _arms_down_motion(n=2)
    camera = place_camera(motion, distance=3.0, height=1.2)
    assert isinstance(camera, CameraPose)
    eye = camera.camera_to_world(np.zeros(3))
    np.testing.assert_allclose(eye, [0.0, 1.2, 3.0], atol=1e-12)
    np.testing.assert_allclose(camera.rotation[2], [0.0, 0.0, -1.0], atol=1e-12)


def test_a_tilted_camera_looks_down_at_the_person_from_its_height():
    # From 2.2 m, tilted down by the angle to the pelvis, the pelvis lies on the optical
    # axis at its 3 m distance (along the slant), and the eye stays where it was.
    motion = _arms_down_motion(n=2)
    pelvis = pelvis_centre(np.asarray(motion.joints[0], dtype=float))
    drop = 2.2 - pelvis[1]
    tilt = np.degrees(np.arctan2(drop, 3.0))
    camera = place_camera(motion, distance=3.0, height=2.2, tilt=tilt)
    np.testing.assert_allclose(
        camera.camera_to_world(np.zeros(3)), [pelvis[0], 2.2, 3.0 + pelvis[2]], atol=1e-12
    )
    np.testing.assert_allclose(
        camera.world_to_camera(pelvis), [0.0, 0.0, np.hypot(3.0, drop)], atol=1e-9
    )
    # Tilting turns the view about the camera's x axis only: the image's x stays level.
    np.testing.assert_allclose(camera.rotation[0], [1.0, 0.0, 0.0], atol=1e-12)
    with pytest.raises(ValueError, match="'camera_tilt'"):
        place_camera(motion, tilt=90.0)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"intrinsics": "kinect1-qvga"}, "'intrinsics'.*Intrinsics"),
        ({"fps": 0.0}, "'fps'"),
        ({"n_frames": 0}, "'n_frames'"),
        ({"distance": -1.0}, "'distance'"),
        ({"rng": "x"}, "'rng'"),
        ({"facing": 400.0}, "'facing'"),
        ({"camera_tilt": -95.0}, "'camera_tilt'"),
    ],
)
def test_build_sequence_errors_name_the_argument(body, kwargs, match):
    with pytest.raises(ValueError, match=match):
        build_sequence(_arms_down_motion(n=2), body=body, **kwargs)


# --- the folder format -----------------------------------------------------------------------


def test_folder_round_trip_keeps_depth_labels_and_truth(sequence, tmp_path):
    paths = write_synthetic(sequence, tmp_path / "out")
    assert paths["ground_truth"].name == "ground_truth.json"
    names = sorted(p.name for p in (tmp_path / "out" / "depth").iterdir())
    assert names == [f"{i:06d}.png" for i in range(len(sequence.frames))]
    truth = json.loads(paths["ground_truth"].read_text())
    assert truth["intrinsics"] == K.to_dict()
    assert truth["fps"] == 30.0
    assert truth["joint_names"] == list(JOINT_NAMES)
    assert truth["angle_names"] == list(ANGLE_NAMES)
    assert [f["index"] for f in truth["frames"]] == list(range(len(sequence.frames)))
    assert np.array(truth["frames"][0]["joints"]).shape == (15, 3)
    assert set(truth["frames"][0]["angles_deg"]) == set(ANGLE_NAMES)

    import imageio.v3 as iio

    raw = iio.imread(tmp_path / "out" / "depth" / "000000.png")
    lab = iio.imread(tmp_path / "out" / "labels" / "000000.png")
    assert raw.dtype == np.uint16 and lab.dtype == np.uint8 and raw.shape == (240, 320)

    back = read_synthetic(tmp_path / "out")
    assert back.name == sequence.name and back.fps == sequence.fps
    assert len(back.frames) == len(sequence.frames)
    for a, b in zip(sequence.frames, back.frames, strict=True):
        assert np.max(np.abs(a.depth - b.depth)) <= 0.0005 + 1e-6  # millimetre rounding
        assert b.intrinsics == K
    for a, b in zip(sequence.reference.labels, back.reference.labels, strict=True):
        np.testing.assert_array_equal(a, b)
    np.testing.assert_allclose(back.reference.joints, sequence.reference.joints, atol=1e-12)
    np.testing.assert_allclose(back.reference.angles, sequence.reference.angles, atol=1e-9)


def test_read_synthetic_errors_name_the_file(sequence, tmp_path):
    out = tmp_path / "bad"
    write_synthetic(sequence, out)
    with pytest.raises(ValueError, match="has no ground_truth.json"):
        read_synthetic(tmp_path)
    with pytest.raises(ValueError, match="does not exist"):
        read_synthetic(tmp_path / "nowhere")
    (out / "depth" / "000003.png").unlink()
    with pytest.raises(ValueError, match=r"000003\.png: missing frame file"):
        read_synthetic(out)
    import imageio.v3 as iio

    iio.imwrite(out / "depth" / "000003.png", np.zeros((240, 320), dtype=np.uint8))
    with pytest.raises(ValueError, match=r"000003\.png: expected a uint16 image"):
        read_synthetic(out)
    (out / "depth" / "000003.png").write_bytes(b"not a png")
    with pytest.raises(ValueError, match=r"000003\.png: not a readable PNG"):
        read_synthetic(out)
    iio.imwrite(out / "depth" / "000003.png", np.zeros((240, 320), dtype=np.uint16))
    iio.imwrite(out / "labels" / "000002.png", np.full((240, 320), 20, dtype=np.uint8))
    with pytest.raises(ValueError, match=r"000002\.png: label values"):
        read_synthetic(out)
    truth = json.loads((out / "ground_truth.json").read_text())
    del truth["fps"]
    (out / "ground_truth.json").write_text(json.dumps(truth))
    with pytest.raises(ValueError, match=r"ground_truth\.json: missing key\(s\) \['fps'\]"):
        read_synthetic(out)
    (out / "ground_truth.json").write_text("{")
    with pytest.raises(ValueError, match=r"ground_truth\.json: not readable JSON"):
        read_synthetic(out)


def test_contact_sheet_shows_depth_beside_labels(sequence, tmp_path):
    import imageio.v3 as iio

    path = contact_sheet(sequence, tmp_path / "sheet.png", frames=4, columns=2)
    image = iio.imread(path)
    # Two tiles per row (each depth | 2 px | labels), 6 px bands; two rows.
    assert image.shape == (2 * 240 + 6, 2 * (2 * 320 + 2) + 6, 3)
    tile_labels = image[:240, 322:642]
    from posedrift.skeleton import PART_COLOURS

    head = np.all(tile_labels == PART_COLOURS[PART_INDEX["head"]], axis=-1)
    assert head.sum() > 50
    with pytest.raises(ValueError, match="outside the sequence"):
        contact_sheet(sequence, tmp_path / "x.png", frames=[99])


def test_stature_scales_the_clip_and_the_rendered_person(body, sequence):
    seq = build_sequence(_arms_down_motion(n=2), body=body, stature=1.6)
    depth, labels = seq.frames[0].depth, seq.reference.labels[0]
    rows = np.flatnonzero((labels > 0).any(axis=1))
    top, bottom = rows[0], rows[-1]
    z_top = depth[top][labels[top] > 0].mean()
    z_bottom = depth[bottom][labels[bottom] > 0].mean()
    height = (bottom - K.cy) * z_bottom / K.fy - (top - K.cy) * z_top / K.fy
    assert height == pytest.approx(1.6, rel=0.02)
    # The truth is scaled with it: same angles, shorter bones, the pelvis still 2.8 m away.
    np.testing.assert_allclose(seq.reference.angles[0], sequence.reference.angles[0], atol=1e-6)
    ref = seq.reference.joints[0]
    arm = np.linalg.norm(ref[JOINT_INDEX["left_hand"]] - ref[JOINT_INDEX["left_shoulder"]])
    ref0 = sequence.reference.joints[0]
    arm0 = np.linalg.norm(ref0[JOINT_INDEX["left_hand"]] - ref0[JOINT_INDEX["left_shoulder"]])
    assert arm / arm0 < 0.95
    pelvis = 0.5 * (ref[JOINT_INDEX["left_hip"]] + ref[JOINT_INDEX["right_hip"]])
    assert pelvis[2] == pytest.approx(2.8)
    with pytest.raises(ValueError, match="'stature'"):
        build_sequence(_arms_down_motion(n=2), body=body, stature=7.0)


def test_rewriting_a_folder_drops_stale_frames(sequence, tmp_path):
    write_synthetic(sequence, tmp_path)
    short = EvaluationSequence(
        name="short",
        frames=sequence.frames[:2],
        reference=type(sequence.reference)(
            joints=sequence.reference.joints[:2],
            angles=sequence.reference.angles[:2],
            labels=sequence.reference.labels[:2],
        ),
    )
    write_synthetic(short, tmp_path)
    assert sorted(p.name for p in (tmp_path / "depth").iterdir()) == ["000000.png", "000001.png"]
    assert sorted(p.name for p in (tmp_path / "labels").iterdir()) == ["000000.png", "000001.png"]
    assert len(read_synthetic(tmp_path).frames) == 2


@pytest.mark.parametrize("n_frames", [8, 9])
def test_there_and_back_repeats_the_first_poses_in_reverse(body, n_frames):
    motion = _arms_down_motion(n=12)
    forward = build_sequence(motion, body=body, n_frames=n_frames)
    both = build_sequence(motion, body=body, n_frames=n_frames, there_and_back=True)
    assert len(both.frames) == n_frames
    half = -(-n_frames // 2)
    ref = both.reference
    for t in range(n_frames):
        np.testing.assert_array_equal(ref.joints[t], ref.joints[n_frames - 1 - t])
        np.testing.assert_array_equal(both.frames[t].depth, both.frames[n_frames - 1 - t].depth)
        np.testing.assert_array_equal(ref.labels[t], ref.labels[n_frames - 1 - t])
    # The first half is the clip as played forward; time still runs forward.
    np.testing.assert_array_equal(ref.joints[:half], forward.reference.joints[:half])
    assert [f.timestamp for f in both.frames] == [f.timestamp for f in forward.frames]


def test_there_and_back_of_a_short_clip_plays_all_of_it_both_ways(body):
    seq = build_sequence(_arms_down_motion(n=4), body=body, n_frames=20, there_and_back=True)
    assert len(seq.frames) == 8  # its 4 frames forward, then backward
    np.testing.assert_array_equal(seq.reference.joints[:4], seq.reference.joints[:3:-1])


def test_in_place_keeps_a_walking_person_in_view_with_the_same_angles(body):
    base = _arms_down_motion(n=30)
    walk = np.linspace(0.0, 2.4, len(base))  # 2.4 m towards the camera
    shifted = Motion(
        base.joints + walk[:, None, None] * np.array([0.0, 0.0, 1.0]),
        {k: v + walk[:, None] * np.array([0.0, 0.0, 1.0]) for k, v in base.extras.items()},
        base.fps,
        "walk",
    )
    kw = {"body": body, "calibration": False}
    walking = build_sequence(shifted, **kw)
    treadmill = build_sequence(shifted, in_place=True, **kw)
    np.testing.assert_allclose(treadmill.reference.angles, walking.reference.angles, atol=1e-9)
    pelvis = treadmill.reference.joints[:, [JOINT_INDEX["right_hip"], JOINT_INDEX["left_hip"]]]
    depth_of_pelvis = pelvis.mean(axis=1)[:, 2]
    assert np.ptp(depth_of_pelvis) < 1e-9  # stays at the protocol distance
    walked = walking.reference.joints[:, JOINT_INDEX["torso"], 2]
    own_step = base.joints[-1, JOINT_INDEX["torso"], 2] - base.joints[0, JOINT_INDEX["torso"], 2]
    # without it, they walk up to the camera
    assert walked[0] - walked[-1] == pytest.approx(2.4 + own_step, abs=1e-6)


@pytest.mark.parametrize("facing", [90.0, 180.0, -90.0])
def test_facing_turns_the_person_not_the_angles(body, sequence, facing):
    turned = build_sequence(_arms_down_motion(), body=body, facing=facing)
    np.testing.assert_allclose(turned.reference.angles, sequence.reference.angles, atol=1e-9)
    joints = turned.reference.joints[0]
    assert facing_yaw(joints) == pytest.approx(abs(facing), abs=1.0)
    # Turned to their left (+90) the person shows the camera their right side.
    right, left = joints[JOINT_INDEX["right_hip"], 2], joints[JOINT_INDEX["left_hip"], 2]
    if facing == 90.0:
        assert right < left - 0.15
    elif facing == -90.0:
        assert left < right - 0.15
    # The camera still looks at the same person from the same distance.
    pelvis = 0.5 * (joints[JOINT_INDEX["left_hip"]] + joints[JOINT_INDEX["right_hip"]])
    front = sequence.reference.joints[0]
    front_pelvis = 0.5 * (front[JOINT_INDEX["left_hip"]] + front[JOINT_INDEX["right_hip"]])
    np.testing.assert_allclose(pelvis, front_pelvis, atol=0.02)
