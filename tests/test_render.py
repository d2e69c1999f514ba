"""The depth renderer and the Kinect-like noise model: analytic geometry first."""

from __future__ import annotations

import numpy as np
import pytest

from posedrift.camera import CameraPose, Intrinsics, backproject, camera_preset
from posedrift.synthetic import Scene, depth_to_mm, kinect_noise, plane_depth, render

K = camera_preset("kinect1-qvga")


def _quad(corners: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return np.asarray(corners, dtype=float), np.array([[0, 1, 2], [0, 2, 3]])


def test_fronto_parallel_square_renders_its_depth_and_extent():
    z = 2.8
    half = 0.3
    verts, faces = _quad([[-half, -half, z], [half, -half, z], [half, half, z], [-half, half, z]])
    out = render(verts, faces, K)
    assert out.depth.dtype == np.float32 and out.labels.dtype == np.uint8
    assert out.depth.shape == out.labels.shape == K.shape
    hit = out.depth > 0
    np.testing.assert_allclose(out.depth[hit], z, atol=1e-6)
    assert np.array_equal(hit, out.labels == 1)
    # Extent: every pixel centre inside the projected square, none outside.
    cols = np.arange(K.width)
    rows = np.arange(K.height)
    u_in = np.abs(cols - K.cx) <= K.fx * half / z
    v_in = np.abs(rows - K.cy) <= K.fy * half / z
    assert np.array_equal(hit, v_in[:, None] & u_in[None, :])
    np.testing.assert_array_equal(out.depth_mm()[hit], 2800)


def test_tilted_plane_matches_ray_plane_intersection():
    # Plane through (0, 0, 2.5) with a normal tilted 35 degrees about Y and 20 about X.
    normal = np.array([np.sin(np.radians(35)), np.sin(np.radians(20)), 1.0])
    normal /= np.linalg.norm(normal)
    point = np.array([0.0, 0.0, 2.5])
    offset = float(normal @ point)
    # A large quad in that plane, covering much of the image.
    e1 = np.cross(normal, [0.0, 1.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(normal, e1)
    corners = [point + 0.9 * (sx * e1 + sy * e2) for sx, sy in ((-1, -1), (1, -1), (1, 1), (-1, 1))]
    verts, faces = _quad(corners)
    out = render(verts, faces, K)
    hit = out.depth > 0
    assert hit.sum() > 10_000
    expected = plane_depth(normal, offset, K)
    assert np.max(np.abs(out.depth[hit] - expected[hit])) < 1e-3  # within 1 mm (float32: ~1e-6)
    # The rendered pixels back-project onto the plane.
    points, _ = backproject(out.depth, K)
    assert np.max(np.abs(points @ normal - offset)) < 1e-3


def test_nearer_triangle_wins_the_z_buffer():
    near_tri = [[-0.5, -0.5, 2.0], [0.5, -0.5, 2.0], [0.0, 0.5, 2.0]]
    far_tri = [[-1.2, -1.2, 3.0], [1.2, -1.2, 3.0], [0.0, 1.2, 3.0]]
    verts = np.array(far_tri + near_tri)
    parts = np.array([4, 4, 4, 9, 9, 9])
    for faces in (np.array([[0, 1, 2], [3, 4, 5]]), np.array([[3, 4, 5], [0, 1, 2]])):
        out = render(verts, faces, K, vertex_parts=parts)
        assert out.depth[K.height // 2, K.width // 2] == pytest.approx(2.0)
        assert out.labels[K.height // 2, K.width // 2] == 10
        assert set(np.unique(out.depth)) == {0.0, 2.0, 3.0}
        np.testing.assert_array_equal(out.labels[out.depth == 3.0], 5)


def test_interpenetrating_triangles_cross_where_the_depths_do():
    # One plane z = 2 + 0.5 x, the other z = 2 - 0.5 x: x < 0 shows the first.
    a = [[-1.0, -0.5, 1.5], [1.0, -0.5, 2.5], [1.0, 0.5, 2.5], [-1.0, 0.5, 1.5]]
    b = [[-1.0, -0.5, 2.5], [1.0, -0.5, 1.5], [1.0, 0.5, 1.5], [-1.0, 0.5, 2.5]]
    verts = np.array(a + b)
    faces = np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]])
    parts = np.array([0] * 4 + [1] * 4)
    out = render(verts, faces, K, vertex_parts=parts)
    row = out.labels[K.height // 2]
    assert row[K.width // 2 - 20] == 1 and row[K.width // 2 + 20] == 2


def test_labels_follow_the_nearest_vertex():
    verts = np.array([[-0.3, -0.3, 2.0], [0.3, -0.3, 2.0], [0.0, 0.3, 2.0]])
    out = render(verts, np.array([[0, 1, 2]]), K, vertex_parts=np.array([0, 1, 2]))
    assert set(np.unique(out.labels)) == {0, 1, 2, 3}
    u_left = int(K.cx - 0.25 * K.fx / 2.0)
    u_right = int(K.cx + 0.25 * K.fx / 2.0)
    v_top = int(K.cy - 0.25 * K.fy / 2.0)  # vertices 0 and 1 have y = -0.3: the image's top
    assert out.labels[v_top, u_left] == 1 and out.labels[v_top, u_right] == 2
    assert out.labels[int(K.cy + 0.2 * K.fy / 2.0), int(K.cx)] == 3


def test_back_face_culling_drops_faces_turned_away():
    z = 2.0
    verts = np.array([[-0.2, -0.2, z], [0.2, -0.2, z], [0.0, 0.2, z]])
    # Seen from the camera with +Y down, (0, 1, 2) runs clockwise in the world (normal +Z, away).
    away = render(verts, np.array([[0, 1, 2]]), K, cull_backfaces=True)
    toward = render(verts, np.array([[0, 2, 1]]), K, cull_backfaces=True)
    assert not away.mask.any()
    assert toward.mask.sum() > 100


def test_geometry_behind_or_outside_the_camera_is_dropped():
    verts = np.array([[-0.2, -0.2, -2.0], [0.2, -0.2, -2.0], [0.0, 0.2, -2.0]])
    assert not render(verts, np.array([[0, 1, 2]]), K).mask.any()
    verts = np.array([[10.0, 10.0, 2.0], [11.0, 10.0, 2.0], [10.0, 11.0, 2.0]])
    assert not render(verts, np.array([[0, 1, 2]]), K).mask.any()
    # Straddling the image border is clipped, not dropped.
    verts = np.array([[-5.0, -0.2, 2.0], [0.0, -0.2, 2.0], [0.0, 0.2, 2.0]])
    assert render(verts, np.array([[0, 1, 2]]), K).mask[:, 0].any()
    empty = render(np.zeros((0, 3)), np.zeros((0, 3), dtype=int), K)
    assert not empty.mask.any() and not empty.depth.any()


def test_large_meshes_are_batched_without_changing_the_result(monkeypatch):
    import posedrift.synthetic._render as module

    verts, faces = _quad([[-1, -1, 2.0], [1, -1, 2.5], [1, 1, 3.0], [-1, 1, 2.5]])
    whole = render(verts, faces, K)
    monkeypatch.setattr(module, "_BATCH", 1000)
    batched = render(verts, faces, K)
    np.testing.assert_array_equal(whole.depth, batched.depth)


def test_scene_floor_and_wall_are_ray_plane_exact_and_unlabelled():
    camera = CameraPose.look_at([0.0, 1.0, 2.8], [0.0, 1.0, 0.0])
    scene = Scene(camera, floor_y=0.0, wall_z=-1.5)
    out = render(np.zeros((0, 3)), np.zeros((0, 3), dtype=int), K, scene=scene)
    assert not out.labels.any()
    # The image centre looks straight at the wall 4.3 m away; the bottom row sees the floor.
    assert out.depth[int(K.cy), int(K.cx)] == pytest.approx(4.3, abs=1e-5)
    points, _ = backproject(out.depth, K)
    world = camera.camera_to_world(points)
    on_floor = np.abs(world[:, 1]) < 1e-4
    on_wall = np.abs(world[:, 2] + 1.5) < 1e-4
    assert np.all(on_floor | on_wall)
    assert on_floor.sum() > 1000 and on_wall.sum() > 1000
    assert np.all(world[on_floor, 2] >= -1.5 - 1e-4)  # no floor beyond the wall
    # A person in front hides the wall and keeps its labels.
    verts, faces = _quad([[-0.3, -0.3, 2.8], [0.3, -0.3, 2.8], [0.3, 0.3, 2.8], [-0.3, 0.3, 2.8]])
    both = render(verts, faces, K, scene=scene)
    assert both.labels[int(K.cy), int(K.cx)] == 1
    assert both.depth[int(K.cy), int(K.cx)] == pytest.approx(2.8)
    assert np.all(both.depth > 0)


def test_depth_mm_rounds_and_clips():
    d = np.array([[0.0, 0.0004, 0.0006, 2.8, 1e3]], dtype=np.float32)
    np.testing.assert_array_equal(depth_to_mm(d), [[0, 0, 1, 2800, 65535]])


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"vertices": np.zeros((3, 2))}, "'vertices'.*3 columns"),
        ({"faces": np.array([[0, 1, 5]])}, "'faces'.*index the 3 vertices"),
        ({"faces": np.array([[0.0, 1.0, 2.0]])}, "'faces'.*integer"),
        ({"vertex_parts": np.array([0, 1])}, "'vertex_parts'.*\\(3,\\)"),
        ({"vertex_parts": np.array([0, 1, 300])}, "'vertex_parts'.*\\[0, 254\\]"),
        ({"intrinsics": (1, 2, 3)}, "'intrinsics'.*Intrinsics"),
        ({"scene": "floor"}, "'scene'.*Scene"),
        ({"near": -1.0}, "'near'"),
    ],
)
def test_render_errors_name_the_argument(kwargs, match):
    args = {
        "vertices": np.array([[0.0, 0.0, 2.0], [0.1, 0.0, 2.0], [0.0, 0.1, 2.0]]),
        "faces": np.array([[0, 1, 2]]),
        "intrinsics": K,
    } | kwargs
    with pytest.raises(ValueError, match=match):
        render(
            args.pop("vertices"),
            args.pop("faces"),
            args.pop("intrinsics"),
            **args,
        )


# --- noise -----------------------------------------------------------------------------------


def test_noise_grows_with_depth_squared_and_is_quantized():
    k = Intrinsics(fx=285.63, fy=285.63, cx=100, cy=100, width=200, height=200)
    assert k.shape == (200, 200)
    sigmas = {}
    for z in (1.0, 2.0, 4.0):
        clean = np.full((200, 200), z, dtype=np.float32)
        noisy = kinect_noise(clean, rng=1, edge_dropout=0.0, hole_rate=0.0)
        assert np.all(noisy > 0)
        assert abs(float(np.mean(noisy)) - z) < 0.01 * z**2
        sigmas[z] = float(np.std(noisy))
        # Depth values sit on the disparity grid: z = b f / (n / 8).
        n = 0.075 * 580.0 / noisy.astype(np.float64) * 8
        np.testing.assert_allclose(n, np.round(n), atol=1e-3 * z**2)
    # Random noise 1.425e-3 z^2 plus quantization (step z^2 / (8 b f)): both scale with z^2.
    for z, s in sigmas.items():
        step = z**2 / (8 * 0.075 * 580.0)
        expected = np.hypot(1.425e-3 * z**2, step / np.sqrt(12))
        assert s == pytest.approx(expected, rel=0.25), (z, s, expected)
    assert sigmas[4.0] / sigmas[1.0] == pytest.approx(16, rel=0.35)


def test_noise_identity_when_everything_is_switched_off():
    rng = np.random.default_rng(0)
    clean = rng.uniform(1.0, 4.0, size=(30, 40)).astype(np.float32)
    clean[5:9, 5:9] = 0.0
    same = kinect_noise(
        clean, rng=0, sigma_coefficient=0.0, subpixel=0, edge_dropout=0.0, hole_rate=0.0
    )
    np.testing.assert_allclose(same, clean, rtol=1e-6)
    assert not np.shares_memory(same, clean)


def test_noise_drops_pixels_at_silhouette_edges():
    depth = np.zeros((60, 60), dtype=np.float32)
    depth[20:40, 20:40] = 2.5
    depth[:, 50:] = 4.0  # a wall at the side: its inner edge is a discontinuity too
    noisy = kinect_noise(depth, rng=3, edge_dropout=1.0, hole_rate=0.0, sigma_coefficient=0.0)
    assert not noisy[20, 20:40].any() and not noisy[20:40, 39].any()  # the square's rim is gone
    assert noisy[21:39, 21:39].all()  # its inside stays
    assert not noisy[:, 50].any() and noisy[:, 51:].all()
    half = kinect_noise(depth, rng=3, edge_dropout=0.5, hole_rate=0.0)
    rim = np.zeros_like(depth, dtype=bool)
    rim[20:40, 20:40] = True
    rim[21:39, 21:39] = False
    lost = (half == 0) & rim
    assert 0.3 < lost.sum() / rim.sum() < 0.7


def test_noise_range_limits_and_holes_and_seed():
    depth = np.full((100, 100), 2.0, dtype=np.float32)
    depth[0, 0] = 0.3
    depth[0, 1] = 9.0
    a = kinect_noise(depth, rng=5, edge_dropout=0.0, hole_rate=0.05)
    assert a[0, 0] == 0 and a[0, 1] == 0
    assert 0.03 < np.mean(a == 0) < 0.07
    np.testing.assert_array_equal(a, kinect_noise(depth, rng=5, edge_dropout=0.0, hole_rate=0.05))


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"edge_dropout": 1.5}, "'edge_dropout'"),
        ({"hole_rate": -0.1}, "'hole_rate'"),
        ({"sigma_coefficient": -1.0}, "'sigma_coefficient'"),
        ({"max_depth": 0.1}, "'max_depth'"),
        ({"subpixel": 2.5}, "'subpixel'"),
        ({"rng": "seed"}, "'rng'"),
    ],
)
def test_noise_errors_name_the_argument(kwargs, match):
    with pytest.raises(ValueError, match=match):
        kinect_noise(np.ones((4, 4)), **kwargs)
    with pytest.raises(ValueError, match="'depth'"):
        kinect_noise(np.ones(4))


# --- the body model --------------------------------------------------------------------------


@pytest.fixture(scope="module")
def body():
    from posedrift.synthetic import BodyModel

    return BodyModel.load_default()


def _front_camera(distance: float = 2.8, height: float = 1.0) -> CameraPose:
    return CameraPose.look_at([0.0, height, distance], [0.0, height, 0.0])


def test_rendered_person_height_matches_the_body(body):
    camera = _front_camera()
    vertices = camera.world_to_camera(body.vertices)
    out = render(vertices, body.faces, K, vertex_parts=body.vertex_parts)
    rows = np.flatnonzero(out.mask.any(axis=1))
    top, bottom = rows[0], rows[-1]
    # Pixel height: exactly the projected extent of the mesh (within a pixel).
    v = K.fy * vertices[:, 1] / vertices[:, 2] + K.cy
    assert abs(top - np.ceil(v.min())) <= 1 and abs(bottom - np.floor(v.max())) <= 1
    # Metric height: the top and bottom rows, back-projected at their rendered depth.
    z_top = out.depth[top][out.mask[top]].mean()
    z_bottom = out.depth[bottom][out.mask[bottom]].mean()
    height = (bottom - K.cy) * z_bottom / K.fy - (top - K.cy) * z_top / K.fy
    assert height == pytest.approx(body.stature, rel=0.02)
    # A taller body at the same distance is proportionally taller in pixels.
    tall = body.with_shape(height=1.05 * body.stature)
    out_tall = render(camera.world_to_camera(tall.vertices), tall.faces, K)
    rows_tall = np.flatnonzero(out_tall.mask.any(axis=1))
    ratio = (rows_tall[-1] - rows_tall[0] + 1) / (bottom - top + 1)
    assert ratio == pytest.approx(1.05, rel=0.02)


def test_t_pose_render_shows_all_15_parts_on_the_right_sides(body):
    from posedrift.skeleton import PART_INDEX, t_pose_joints

    joints = t_pose_joints(body.stature)
    camera = _front_camera()
    out = render(
        camera.world_to_camera(body.pose(joints)), body.faces, K, vertex_parts=body.vertex_parts
    )
    present = set(np.unique(out.labels)) - {0}
    assert present == set(range(1, 16))
    counts = np.bincount(out.labels.ravel(), minlength=16)
    assert counts[1:].min() >= 10  # every part is more than a speck
    # Facing the camera, the person's right hand appears on the image's left.
    cols = np.arange(K.width)
    right = out.labels == PART_INDEX["right_hand"] + 1
    left = out.labels == PART_INDEX["left_hand"] + 1
    assert cols[right.any(axis=0)].mean() < K.cx < cols[left.any(axis=0)].mean()


def test_back_face_culling_does_not_change_a_posed_body(body):
    from posedrift.skeleton import JOINT_INDEX, t_pose_joints

    joints = t_pose_joints(body.stature)
    # Fold the left arm across the chest (self-occlusion) and bend a knee.
    joints[JOINT_INDEX["left_elbow"]] = joints[JOINT_INDEX["left_shoulder"]] + [0.0, -0.2, 0.2]
    joints[JOINT_INDEX["left_hand"]] = joints[JOINT_INDEX["left_elbow"]] + [-0.3, 0.05, 0.02]
    joints[JOINT_INDEX["right_foot"]] = joints[JOINT_INDEX["right_knee"]] + [0.0, -0.3, -0.3]
    vertices = _front_camera().world_to_camera(body.pose(joints))
    plain = render(vertices, body.faces, K, vertex_parts=body.vertex_parts)
    culled = render(vertices, body.faces, K, vertex_parts=body.vertex_parts, cull_backfaces=True)
    np.testing.assert_array_equal(plain.depth, culled.depth)
    np.testing.assert_array_equal(plain.labels, culled.labels)


def test_scene_options_floor_only_wall_only_and_range():
    camera = CameraPose.look_at([0.0, 1.0, 2.8], [0.0, 1.0, 0.0])
    empty = (np.zeros((0, 3)), np.zeros((0, 3), dtype=int))
    floor = render(*empty, K, scene=Scene(camera, wall_z=None, max_depth=6.0)).depth
    assert not floor[: int(K.cy) + 1].any()  # nothing at or above the horizon
    assert floor.max() <= 6.0 and floor[-1].min() > 0
    wall = render(*empty, K, scene=Scene(camera, floor_y=None)).depth
    np.testing.assert_allclose(wall[wall > 0], 4.3, atol=1e-5)
    assert np.all(wall > 0)
    with pytest.raises(ValueError, match="'camera'.*CameraPose"):
        Scene("camera")
    with pytest.raises(ValueError, match="'max_depth'"):
        Scene(camera, max_depth=0.0)
