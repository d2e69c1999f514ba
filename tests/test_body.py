"""The body model: asset, parts, skinning from joint positions, shape."""

from __future__ import annotations

from importlib import resources

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from posedrift.skeleton import EXTRA_POINT_NAMES, JOINT_INDEX, PART_INDEX, PART_NAMES
from posedrift.synthetic import BodyModel

J = JOINT_INDEX


@pytest.fixture(scope="module")
def body() -> BodyModel:
    return BodyModel.load_default()


def _length(joints: np.ndarray, a: str, b: str) -> float:
    return float(np.linalg.norm(joints[J[a]] - joints[J[b]]))


def _t_pose(body: BodyModel) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """The body's own skeleton (rest bone lengths) in a T-pose, with extra points."""
    r = body.rest_joints
    out = r.copy()
    extras = {"head_top": body.rest_extras["head_top"].copy()}
    for side, sign in (("right", -1.0), ("left", 1.0)):
        sh = r[J[f"{side}_shoulder"]]
        ua = _length(r, f"{side}_shoulder", f"{side}_elbow")
        fa = _length(r, f"{side}_elbow", f"{side}_hand")
        hand = np.linalg.norm(body.rest_extras[f"{side}_hand_tip"] - r[J[f"{side}_hand"]])
        out[J[f"{side}_elbow"]] = sh + [sign * ua, 0, 0]
        out[J[f"{side}_hand"]] = sh + [sign * (ua + fa), 0, 0]
        extras[f"{side}_hand_tip"] = sh + [sign * (ua + fa + hand), 0, 0]
        hip = r[J[f"{side}_hip"]]
        th = _length(r, f"{side}_hip", f"{side}_knee")
        sk = _length(r, f"{side}_knee", f"{side}_foot")
        out[J[f"{side}_knee"]] = hip - [0, th, 0]
        out[J[f"{side}_foot"]] = hip - [0, th + sk, 0]
        toe = body.rest_extras[f"{side}_toe"] - r[J[f"{side}_foot"]]
        extras[f"{side}_toe"] = out[J[f"{side}_foot"]] + toe
    return out, extras


def _elbow_bent(body: BodyModel) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Right arm hanging beside the body, elbow bent 90 degrees, forearm pointing forward."""
    joints, extras = _t_pose(body)
    r = body.rest_joints
    sh = joints[J["right_shoulder"]]
    ua = _length(r, "right_shoulder", "right_elbow")
    fa = _length(r, "right_elbow", "right_hand")
    down = np.array([-0.25, -1.0, 0.0]) / np.hypot(0.25, 1.0)
    elbow = sh + ua * down
    joints[J["right_elbow"]] = elbow
    joints[J["right_hand"]] = elbow + [0, 0, fa]
    hand = np.linalg.norm(body.rest_extras["right_hand_tip"] - r[J["right_hand"]])
    extras["right_hand_tip"] = elbow + [0, 0, fa + hand]
    return joints, extras


def test_asset_format() -> None:
    ref = resources.files("posedrift") / "data" / "body_model.npz"
    with resources.as_file(ref) as path:
        assert path.stat().st_size < 4_000_000
        with np.load(path, allow_pickle=False) as z:
            for name in z.files:
                assert z[name].dtype.kind in "fiuU", name
                assert z[name].dtype not in (np.float64, np.int64), name
    license_ref = resources.files("posedrift") / "data" / "BODY_MODEL_LICENSE.md"
    assert "CC0" in license_ref.read_text()


def test_shapes(body: BodyModel) -> None:
    v = len(body.vertices)
    assert 2000 < v < 10000
    assert body.faces.dtype == np.int32 and body.faces.shape[1] == 3
    assert body.faces.min() == 0 and body.faces.max() == v - 1
    assert body.vertex_parts.shape == (v,) and body.vertex_parts.dtype == np.uint8
    assert body.rest_joints.shape == (15, 3)
    assert set(body.rest_extras) == set(EXTRA_POINT_NAMES)
    np.testing.assert_allclose(body.skin_weights.sum(axis=1), 1.0, atol=1e-5)


def test_world_frame(body: BodyModel) -> None:
    v, j = body.vertices, body.rest_joints
    assert abs(v[:, 1].min()) < 1e-6  # soles on the floor
    pelvis = 0.5 * (j[J["right_hip"]] + j[J["left_hip"]])
    np.testing.assert_allclose(pelvis[[0, 2]], 0.0, atol=1e-6)
    assert 1.6 < body.stature < 1.85
    # Person's right at -X, facing +Z: the nose is the most forward point of the head.
    assert j[J["right_hand"], 0] < 0 < j[J["left_hand"], 0]
    head = v[body.vertex_parts == PART_INDEX["head"]]
    nose = head[np.argmax(head[:, 2])]
    assert abs(nose[0]) < 0.01 and nose[1] > j[J["neck"], 1]
    # Joints inside the body's bounding box, ordered top to bottom.
    assert j[J["head"], 1] > j[J["neck"], 1] > j[J["torso"], 1] > j[J["right_hip"], 1]
    assert j[J["right_hip"], 1] > j[J["right_knee"], 1] > j[J["right_foot"], 1] > 0
    assert body.rest_extras["head_top"][1] == pytest.approx(body.stature, abs=0.01)


def test_every_part_connected(body: BodyModel) -> None:
    f = body.faces
    parts = body.vertex_parts
    n = len(parts)
    for p, name in enumerate(PART_NAMES):
        members = np.flatnonzero(parts == p)
        assert members.size > 20, name
        edges = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
        keep = (parts[edges[:, 0]] == p) & (parts[edges[:, 1]] == p)
        e = edges[keep]
        graph = sp.coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n, n))
        _, labels = connected_components(graph, directed=False)
        assert np.unique(labels[members]).size == 1, name


def test_parts_where_expected(body: BodyModel) -> None:
    v, parts, j = body.vertices, body.vertex_parts, body.rest_joints
    for name, lo, hi in (
        ("head", j[J["neck"], 1] - 0.05, body.stature + 1e-6),
        ("right_foot", 0.0, j[J["right_foot"], 1] + 0.06),
        ("right_hand", 0.0, j[J["right_hand"], 1] + 0.05),
    ):
        y = v[parts == PART_INDEX[name], 1]
        assert y.min() >= lo and y.max() <= hi, name
    # Each part's vertices lie around its own bone (left parts at +X).
    for name in PART_NAMES:
        x = v[parts == PART_INDEX[name], 0].mean()
        if name.startswith("left"):
            assert x > 0.03, name
        elif name.startswith("right"):
            assert x < -0.03, name
        else:
            assert abs(x) < 0.01, name


@pytest.mark.parametrize("with_extras", [True, False])
def test_identity(body: BodyModel, with_extras: bool) -> None:
    extras = body.rest_extras if with_extras else None
    np.testing.assert_allclose(body.pose(body.rest_joints, extras), body.vertices, atol=1e-5)


def test_elbow_bent_moves_hand(body: BodyModel) -> None:
    joints, extras = _elbow_bent(body)
    verts = body.pose(joints, extras)
    sel = body.vertex_parts == PART_INDEX["right_hand"]
    hand = verts[sel]
    wrist, tip = joints[J["right_hand"]], extras["right_hand_tip"]

    def distances(points: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        d = b - a
        s = np.clip((points - a) @ d / (d @ d), 0, 1)
        return np.linalg.norm(points - (a + s[:, None] * d), axis=1)

    # The hand lies around its wrist->finger-tip segment as it did at rest.
    rest = distances(
        body.vertices[sel], body.rest_joints[J["right_hand"]], body.rest_extras["right_hand_tip"]
    )
    np.testing.assert_allclose(distances(hand, wrist, tip), rest, atol=0.003)
    assert np.linalg.norm(hand.mean(axis=0) - 0.5 * (wrist + tip)) < 0.03
    # The whole hand is in front of the body, not inside the torso.
    torso = verts[
        np.isin(body.vertex_parts, [PART_INDEX["upper_torso"], PART_INDEX["lower_torso"]])
    ]
    gap, _ = cKDTree(torso).query(hand)
    assert gap.min() > 0.05
    # Forearm vertices near the forearm segment.
    fore = verts[body.vertex_parts == PART_INDEX["right_forearm"]]
    assert distances(fore, joints[J["right_elbow"]], wrist).max() < 0.08


def test_rigid_parts_keep_their_shape(body: BodyModel) -> None:
    joints, extras = _elbow_bent(body)
    verts = body.pose(joints, extras)
    for name in ("right_forearm", "right_hand", "right_shank", "head", "left_foot"):
        p = PART_INDEX[name]
        sel = np.flatnonzero(body.skin_weights[:, p] > 0.999)
        assert sel.size >= 8, name
        rest = body.vertices[sel]
        posed = verts[sel]
        d_rest = np.linalg.norm(rest[:, None] - rest[None], axis=-1)
        d_posed = np.linalg.norm(posed[:, None] - posed[None], axis=-1)
        assert np.abs(d_posed - d_rest).max() < 1e-3, name


def test_rigid_motion_invariance(body: BodyModel) -> None:
    joints, extras = _elbow_bent(body)
    rot = Rotation.from_euler("xyz", [20, -65, 10], degrees=True).as_matrix()
    shift = np.array([0.4, -0.2, 2.5])
    base = body.pose(joints, extras)
    moved = body.pose(joints @ rot.T + shift, {k: rot @ v + shift for k, v in extras.items()})
    np.testing.assert_allclose(moved, base @ rot.T + shift, atol=1e-6)
    # Also without extra points.
    base = body.pose(joints)
    np.testing.assert_allclose(body.pose(joints @ rot.T + shift), base @ rot.T + shift, atol=1e-6)


def test_joints_land_where_asked(body: BodyModel) -> None:
    """Vertices around a joint follow it; a longer bone stretches its part."""
    joints, extras = _t_pose(body)
    long = joints.copy()
    stretch = 0.08  # shanks 8 cm longer: ankles and feet move down
    for side in ("right", "left"):
        long[J[f"{side}_foot"], 1] -= stretch
        extras[f"{side}_toe"] = extras[f"{side}_toe"] - [0, stretch, 0]
    lifted = long.copy()
    lifted[:, 1] += stretch
    lifted_extras = {k: v + [0, stretch, 0] for k, v in extras.items()}
    lifted_extras["head_top"] = extras["head_top"] + [0, stretch, 0]
    ref = body.pose(*_t_pose(body))
    verts = body.pose(lifted, lifted_extras)
    feet = np.isin(body.vertex_parts, [PART_INDEX["right_foot"], PART_INDEX["left_foot"]])
    # Feet keep their shape and stay on the floor; the head rises by the stretch.
    np.testing.assert_allclose(verts[feet], ref[feet], atol=2e-3)
    head = body.vertex_parts == PART_INDEX["head"]
    np.testing.assert_allclose(verts[head], ref[head] + [0, stretch, 0], atol=2e-3)
    shank = body.skin_weights[:, PART_INDEX["right_shank"]] > 0.99
    ratio = np.ptp(verts[shank, 1]) / np.ptp(ref[shank, 1])
    length = _length(body.rest_joints, "right_knee", "right_foot")
    assert ratio == pytest.approx((length + stretch) / length, rel=0.02)


def test_height_scales_stature(body: BodyModel) -> None:
    for height in (1.5, 1.9):
        tall = body.with_shape(height=height)
        assert tall.stature == pytest.approx(height, rel=0.01)
        np.testing.assert_allclose(tall.rest_joints, body.rest_joints * height / body.stature)
        np.testing.assert_allclose(tall.pose(tall.rest_joints), tall.vertices, atol=1e-5)
        # Posed on the T-pose of its own skeleton, the body is as tall as asked.
        joints, extras = _t_pose(tall)
        verts = tall.pose(joints, extras)
        assert np.ptp(verts[:, 1]) == pytest.approx(height, rel=0.01)


def test_girth_scales_across_bones(body: BodyModel) -> None:
    wide = body.with_shape(girth=1.2)
    np.testing.assert_allclose(wide.rest_joints, body.rest_joints, atol=1e-6)
    assert wide.stature == pytest.approx(body.stature, rel=0.01)
    w = body.skin_weights
    trunk = w[:, PART_INDEX["upper_torso"]] + w[:, PART_INDEX["lower_torso"]] > 0.999
    waist = np.abs(body.vertices[:, 1] - body.rest_joints[J["torso"], 1]) < 0.05
    for name, a, b in (("right_thigh", "right_hip", "right_knee"), ("torso", "neck", "torso")):
        sel = (trunk & waist) if name == "torso" else w[:, PART_INDEX[name]] > 0.999
        assert sel.sum() > 10, name
        p, q = body.rest_joints[J[a]], body.rest_joints[J[b]]
        d = (q - p) / np.linalg.norm(q - p)

        def radius(v: np.ndarray, p: np.ndarray = p, d: np.ndarray = d) -> np.ndarray:
            off = v - p
            return np.linalg.norm(off - (off @ d)[:, None] * d, axis=1)

        ratio = radius(wide.vertices[sel]).mean() / radius(body.vertices[sel]).mean()
        assert ratio == pytest.approx(1.2, rel=0.02), name
    # Head, hands and feet keep their size.
    head = w[:, PART_INDEX["head"]] > 0.999
    assert np.ptp(wide.vertices[head, 0]) == pytest.approx(np.ptp(body.vertices[head, 0]), rel=0.01)


def test_morphs(body: BodyModel) -> None:
    assert {"heavy", "thin", "muscular", "female"} <= set(body.morph_names)
    heavy = body.with_shape(morphs={"heavy": 1.0})
    waist = np.abs(body.vertices[:, 1] - body.rest_joints[J["torso"], 1] + 0.1) < 0.02

    def width(b: BodyModel) -> float:
        sel = waist & (np.abs(b.vertices[:, 0]) < 0.2)
        return float(np.ptp(b.vertices[sel, 2]))

    assert width(heavy) > 1.05 * width(body)
    thin = body.with_shape(morphs={"thin": 1.0})
    assert width(thin) < width(body)
    for shaped in (heavy, thin, body.with_shape(morphs={"female": 1.0}, height=1.65)):
        assert abs(shaped.vertices[:, 1].min()) < 1e-9
        np.testing.assert_allclose(shaped.pose(shaped.rest_joints), shaped.vertices, atol=1e-5)
    female = body.with_shape(morphs={"female": 1.0})
    assert female.stature < body.stature


def test_pose_is_fast_enough(body: BodyModel) -> None:
    import time

    joints, extras = _elbow_bent(body)
    body.pose(joints, extras)
    times = []
    for _ in range(5):
        t0 = time.perf_counter()
        body.pose(joints, extras)
        times.append(time.perf_counter() - t0)
    assert np.median(times) < 0.05  # generous bound on a shared machine; typical ~2 ms


def test_pose_errors(body: BodyModel) -> None:
    with pytest.raises(ValueError, match=r"'joints' argument of BodyModel.pose must have shape"):
        body.pose(np.zeros((14, 3)))
    bad = body.rest_joints.copy()
    bad[3, 0] = np.nan
    with pytest.raises(ValueError, match="finite"):
        body.pose(bad)
    with pytest.raises(ValueError, match="unknown point 'nose'"):
        body.pose(body.rest_joints, {"nose": np.zeros(3)})
    with pytest.raises(ValueError, match="finite"):
        body.pose(body.rest_joints, {"head_top": [0.0, np.inf, 0.0]})
    with pytest.raises(ValueError, match=r"'right_toe' to a finite \(3,\) point"):
        body.pose(body.rest_joints, {"right_toe": [0.0, 1.0]})
    # An extra point given as NaN is unknown, hence not used.
    nan = {"right_hand_tip": np.full(3, np.nan)}
    np.testing.assert_allclose(body.pose(body.rest_joints, nan), body.vertices, atol=1e-5)
    same = body.rest_joints.copy()
    same[J["right_elbow"]] = same[J["right_hand"]]
    with pytest.raises(ValueError, match="right_forearm bone at the same place"):
        body.pose(same)


def test_shape_errors(body: BodyModel) -> None:
    with pytest.raises(ValueError, match="unknown morph 'wings'"):
        body.with_shape(morphs={"wings": 1.0})
    with pytest.raises(ValueError, match="'height' parameter"):
        body.with_shape(height=-1.0)
    with pytest.raises(ValueError, match="'girth' parameter"):
        body.with_shape(girth=0.0)


def test_load_errors(tmp_path) -> None:
    path = tmp_path / "bad.npz"
    np.savez(path, format_version=np.array(99))
    with pytest.raises(ValueError, match="format version 99"):
        BodyModel.load(path)
    names = tmp_path / "names.npz"
    np.savez(names, format_version=np.array(1), part_names=np.array(["head"]))
    with pytest.raises(ValueError, match="has part_names"):
        BodyModel.load(names)
    junk = tmp_path / "junk.npz"
    junk.write_bytes(b"not a zip")
    with pytest.raises(ValueError, match="Cannot read body model file"):
        BodyModel.load(junk)


def test_face_parts(body: BodyModel) -> None:
    fp = body.face_parts
    assert fp.shape == (len(body.faces),) and fp.dtype == np.uint8
    p = body.vertex_parts[body.faces]
    # Where at least two corners agree, the face takes their part.
    agree = p[:, 0] == p[:, 1]
    np.testing.assert_array_equal(fp[agree], p[agree, 0])
    assert set(np.unique(fp)) == set(range(len(PART_NAMES)))


def test_knee_hinge_sets_thigh_twist(body: BodyModel) -> None:
    """A knee bent with the shank pointing outward turns the kneecap inward."""
    joints, extras = _t_pose(body)
    r = body.rest_joints
    knee = joints[J["right_knee"]]
    shank = _length(r, "right_knee", "right_foot")
    joints[J["right_foot"]] = knee + [-shank, 0.0, 0.0]  # the person's right is -X
    del extras["right_toe"]
    verts = body.pose(joints, extras)
    rest_knee = r[J["right_knee"]]
    near = np.linalg.norm(body.vertices - rest_knee, axis=1) < 0.15
    thigh = body.skin_weights[:, PART_INDEX["right_thigh"]] > 0.9
    front = near & thigh & (body.vertices[:, 2] > rest_knee[2] + 0.03)
    assert front.sum() > 5
    # The front of the thigh above the knee now faces the midline (+X for the right leg).
    assert verts[front, 0].mean() > knee[0] + 0.02
    # Straight knee: it stays in front.
    joints2, extras2 = _t_pose(body)
    verts2 = body.pose(joints2, extras2)
    assert verts2[front, 2].mean() > joints2[J["right_knee"], 2] + 0.02


def test_parts_start_at_their_joints(body: BodyModel) -> None:
    """Each limb part begins at its proximal joint (hand at the wrist, shank at the knee)."""
    v, parts = body.vertices, body.vertex_parts
    ends = {
        "head": ("neck", "head"),
        "right_forearm": ("right_elbow", "right_hand"),
        "left_forearm": ("left_elbow", "left_hand"),
        "right_hand": ("right_hand", "right_hand_tip"),
        "left_hand": ("left_hand", "left_hand_tip"),
        "right_shank": ("right_knee", "right_foot"),
        "left_shank": ("left_knee", "left_foot"),
        "right_thigh": ("right_hip", "right_knee"),
        "left_thigh": ("left_hip", "left_knee"),
    }

    def point(name: str) -> np.ndarray:
        return body.rest_joints[J[name]] if name in J else body.rest_extras[name]

    for part, (a, b) in ends.items():
        p, q = point(a), point(b)
        d = (q - p) / np.linalg.norm(q - p)
        s = (v[parts == PART_INDEX[part]] - p) @ d
        assert -0.03 < s.min() < 0.03, part
        assert s.max() < np.linalg.norm(q - p) + 0.08, part
    # The torso split lies between the pelvis and the neck, near the lowest ribs.
    upper = v[parts == PART_INDEX["upper_torso"], 1].min()
    torso_y = body.rest_joints[J["torso"], 1]
    assert torso_y - 0.12 < upper < torso_y


def test_mesh_is_closed_and_outward(body: BodyModel) -> None:
    f = body.faces
    directed = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    assert len(np.unique(directed, axis=0)) == len(directed)
    _, counts = np.unique(np.sort(directed, axis=1), axis=0, return_counts=True)
    assert np.all(counts == 2)  # watertight, manifold
    v = body.vertices
    volume = np.einsum("ij,ij->i", v[f[:, 0]], np.cross(v[f[:, 1]], v[f[:, 2]])).sum() / 6
    assert 0.05 < volume < 0.09  # m^3, counter-clockwise seen from outside (~60-75 kg)
