"""Visualization: label maps, side-by-side video, angle plots, the offline 3-D viewer."""

from __future__ import annotations

import importlib.util
import json
import re
import shutil
import subprocess
import tempfile
from html.parser import HTMLParser
from pathlib import Path

import imageio.v3 as iio
import numpy as np
import pytest

from posedrift.camera import DepthFrame, camera_preset, project
from posedrift.evaluation import Reference
from posedrift.io import UnreadableFrame
from posedrift.skeleton import JOINT_INDEX, PART_COLOURS, joint_angles, t_pose_joints
from posedrift.tracking import FrameResult, FrameStatus
from posedrift.visualization import (
    DATA_ELEMENT_ID,
    draw_label_image,
    draw_points_image,
    draw_skeleton,
    plot_angles,
    render_posed_body,
    write_video,
    write_viewer,
)

QVGA = camera_preset("kinect1-qvga")
HEAD = PART_COLOURS[0]


def _pose(i: int, n: int) -> np.ndarray:
    """A T-pose (camera frame, 2.8 m away) whose arms lower by 60 degrees over n frames."""
    joints = t_pose_joints(1.75)
    angle = np.radians(60.0 * i / max(n - 1, 1))
    for side, sign in (("left", 1.0), ("right", -1.0)):
        shoulder = joints[JOINT_INDEX[f"{side}_shoulder"]]
        for joint, length in (("_elbow", 0.186 * 1.75), ("_hand", 0.332 * 1.75)):
            direction = np.array([sign * np.cos(angle), -np.sin(angle), 0.0])
            joints[JOINT_INDEX[side + joint]] = shoulder + length * direction
    return joints * [1.0, -1.0, -1.0] + [0.0, 0.9, 2.8]


def _scene(n: int = 5, *, lost: tuple[int, ...] = ()) -> tuple[list, list[FrameResult]]:
    """Depth frames (a box-ish silhouette) and results with points sampled along the bones."""
    rng = np.random.default_rng(0)
    frames, results = [], []
    for i in range(n):
        joints = _pose(i, n)
        depth = np.zeros(QVGA.shape, np.float32)
        uv = np.rint(project(joints, QVGA)).astype(int)
        for u, v in uv:
            depth[max(v - 6, 0) : v + 6, max(u - 6, 0) : u + 6] = 2.8
        frames.append(DepthFrame(depth, QVGA, index=i, timestamp=i / 30))
        if i in lost:
            results.append(FrameResult.empty(i, FrameStatus.LOST, "lost", timestamp=i / 30))
            continue
        labels = rng.integers(0, 15, 300)
        part_joint = np.array([0, 1, 8, 2, 3, 4, 5, 6, 7, 9, 10, 11, 12, 13, 14])
        points = joints[part_joint[labels]] + rng.normal(0, 0.02, (300, 3))
        results.append(
            FrameResult(
                i,
                FrameStatus.TRACKED,
                joints,
                np.ones(15),
                points=points,
                labels=labels,
                timestamp=i / 30,
            )
        )
    return frames, results


def _colour_present(image: np.ndarray, colour, tol: int = 0) -> int:
    return int((np.abs(image[..., :3].astype(int) - colour) <= tol).all(axis=-1).sum())


# -- pictures ---------------------------------------------------------------------------------


def test_label_image_colours_and_conventions():
    labels = np.array([[0, 1, 2], [15, 16, 0]], dtype=np.uint8)
    rgb = draw_label_image(labels)
    assert rgb.shape == (2, 3, 3) and rgb.dtype == np.uint8
    assert rgb[0, 0].tolist() == [0, 0, 0]
    assert rgb[0, 1].tolist() == list(PART_COLOURS[0])
    assert rgb[1, 0].tolist() == list(PART_COLOURS[14])
    assert rgb[1, 1].tolist() == [128, 128, 128]  # not a part
    forest = draw_label_image(np.array([[-1, 0, 14]], dtype=np.int16), zero_based=True)
    assert forest[0].tolist() == [[0, 0, 0], list(PART_COLOURS[0]), list(PART_COLOURS[14])]
    with pytest.raises(ValueError, match=r"'labels' of draw_label_image must be a 2-D integer"):
        draw_label_image(np.zeros((2, 2)))


def test_points_land_on_their_pixels_in_their_colours():
    point = np.array([[0.1, -0.2, 2.0]])
    u, v = np.rint(project(point, QVGA)[0]).astype(int)
    image = draw_points_image(point, np.array([3]), QVGA, radius=0)
    assert image[v, u].tolist() == list(PART_COLOURS[3])
    assert _colour_present(image, PART_COLOURS[3]) == 1
    behind = draw_points_image(np.array([[0.0, 0.0, -1.0]]), np.array([0]), QVGA)
    assert not behind.any()


def test_skeleton_draws_bones_and_skips_unknown_joints():
    joints = _pose(0, 2)
    image = draw_skeleton(np.zeros((*QVGA.shape, 3), np.uint8), joints, QVGA, width=1)
    uv = project(joints, QVGA)
    middle = np.rint(0.5 * (uv[JOINT_INDEX["left_hip"]] + uv[JOINT_INDEX["left_knee"]])).astype(int)
    assert image[middle[1], middle[0]].tolist() == [255, 255, 255]
    joints[JOINT_INDEX["left_knee"]] = np.nan
    image = draw_skeleton(np.zeros((*QVGA.shape, 3), np.uint8), joints, QVGA, width=1)
    assert image[middle[1], middle[0]].tolist() == [0, 0, 0]


# -- video ------------------------------------------------------------------------------------


def test_gif_has_one_picture_per_frame_with_three_panels(tmp_path):
    frames, results = _scene(4, lost=(2,))
    frames[1] = UnreadableFrame(1, "x/000001.png", "truncated")
    path = write_video(frames, results, tmp_path / "v.gif", fps=10)
    movie = iio.imread(path, index=None)
    assert movie.shape[0] == 4
    assert movie.shape[1:3] == (240, 3 * 320 + 2 * 2)
    labels_panel = movie[0][:, 322:642]
    head_v, head_u = np.rint(project(results[0].joints[:1], QVGA)[0, ::-1]).astype(int)
    assert _colour_present(labels_panel, HEAD, tol=8) > 0
    skeleton_panel = movie[0][:, 644:]
    assert _colour_present(skeleton_panel, (255, 255, 255), tol=8) > 20
    depth_panel = movie[0][:, :320]
    assert depth_panel[head_v, head_u].max() > 100  # the silhouette at the head
    assert movie[1][30:, :320].max() < 50  # the unreadable frame: a black depth panel
    assert _colour_present(movie[2][:, 322:642], HEAD, tol=8) == 0  # lost: no points


def test_video_errors(tmp_path):
    frames, results = _scene(2)
    with pytest.raises(ValueError, match="one result per frame. Got 2 frames and 1 results"):
        write_video(frames, results[:1], tmp_path / "v.gif")
    with pytest.raises(ValueError, match=r"writes \.gif or \.mp4"):
        write_video(frames, results, tmp_path / "v.avi")
    with pytest.raises(ValueError, match="needs 'intrinsics'"):
        write_video([None, None], results, tmp_path / "v.gif")
    if importlib.util.find_spec("imageio_ffmpeg") is None:
        with pytest.raises(ValueError, match="needs imageio-ffmpeg"):
            write_video(frames, results, tmp_path / "v.mp4")


def test_mp4_when_imageio_ffmpeg_is_installed(tmp_path):
    imageio_ffmpeg = pytest.importorskip("imageio_ffmpeg")
    frames, results = _scene(6)
    path = write_video(frames, results, tmp_path / "v.mp4", fps=10)
    run = subprocess.run(
        [imageio_ffmpeg.get_ffmpeg_exe(), "-loglevel", "error", "-i", str(path)]
        + ["-f", "rawvideo", "-pix_fmt", "rgb24", "-"],
        capture_output=True,
        check=True,
    )
    movie = np.frombuffer(run.stdout, np.uint8).reshape(-1, 240, 976, 3)
    assert movie.shape[0] == 6
    labels_panel = movie[0][:240, 322:642].astype(int)
    assert (np.abs(labels_panel - HEAD) <= 40).all(-1).sum() > 0  # lossy, but the colours survive


def _body_model():
    try:
        from posedrift.synthetic import BodyModel

        return BodyModel.load_default()
    except (ImportError, ValueError, FileNotFoundError, OSError) as exc:
        pytest.skip(f"body model not available: {exc}")


def test_posed_body_render_overlays_the_joints(tmp_path):
    body = _body_model()
    joints = _pose(2, 5)
    image = render_posed_body(joints, QVGA, body=body)
    head_u, head_v = np.rint(project(joints[:1], QVGA)[0]).astype(int)
    assert _colour_present(image[head_v - 4 : head_v + 5, head_u - 4 : head_u + 5], HEAD, 80) > 10
    # the body spans the skeleton's height in the image
    rows = np.flatnonzero(image.any(axis=(1, 2)))
    uv = project(joints, QVGA)
    assert rows.min() < uv[:, 1].min() and rows.max() > uv[:, 1].max()
    frames, results = _scene(2)
    movie = iio.imread(write_video(frames, results, tmp_path / "b.gif", body=body), index=None)
    assert movie.shape[2] == 4 * 320 + 3 * 2
    with pytest.raises(ValueError, match="needs 15 known joints"):
        render_posed_body(np.full((15, 3), np.nan), QVGA, body=body)


# -- angle plots ------------------------------------------------------------------------------


def test_angle_plot_with_reference(tmp_path):
    _, results = _scene(6, lost=(3,))
    truth = np.array([joint_angles(_pose(i, 6)) for i in range(6)])
    path = plot_angles(results, tmp_path / "angles.png", reference=truth, title="test")
    image = iio.imread(path)
    assert image.shape[0] > 600 and image.shape[1] > 600
    assert _colour_present(image, (214, 39, 40), tol=30) > 100  # the dashed reference (C3)
    reference = Reference(joints=np.stack([_pose(i, 6) for i in range(6)]), angles=truth)
    plot_angles(results, tmp_path / "ref.png", reference=reference, fps=None)
    with pytest.raises(ValueError, match=r"6 frames of 8 angles.*Got shape \(5, 8\)"):
        plot_angles(results, tmp_path / "bad.png", reference=truth[:5])
    with pytest.raises(ValueError, match="no results"):
        plot_angles([], tmp_path / "none.png")


# -- the HTML viewer --------------------------------------------------------------------------


class _Page(HTMLParser):
    def __init__(self) -> None:
        super().__init__()
        self.tags: list[tuple[str, dict]] = []
        self.data: str | None = None
        self._in_data = False

    def handle_starttag(self, tag, attrs):
        attrs = dict(attrs)
        self.tags.append((tag, attrs))
        self._in_data = tag == "script" and attrs.get("id") == DATA_ELEMENT_ID

    def handle_endtag(self, tag):
        self._in_data = False

    def handle_data(self, data):
        if self._in_data:
            self.data = (self.data or "") + data


def _read_page(path: Path) -> tuple[_Page, dict, str]:
    text = path.read_text(encoding="utf-8")
    page = _Page()
    page.feed(text)
    page.close()
    assert page.data is not None, "the page embeds no data element"
    return page, json.loads(page.data), text


def test_viewer_is_self_contained_and_embeds_the_data(tmp_path):
    _, results = _scene(4, lost=(1,))
    path = write_viewer(results, tmp_path / "view.html", title="test </script> & <b>", fps=12)
    page, data, text = _read_page(path)
    assert not re.search(r"(?i)(https?:|ftp:|//[a-z0-9.-]+\.[a-z]{2,})", text)
    for tag, attrs in page.tags:
        assert "src" not in attrs and "href" not in attrs, (tag, attrs)
        assert tag not in ("link", "img", "iframe", "object", "embed")
    assert sum(tag == "canvas" for tag, _ in page.tags) == 1
    assert any(a.get("type") == "range" for t, a in page.tags if t == "input")
    assert data["title"] == "test </script> & <b>" and data["fps"] == 12
    assert len(data["frames"]) == 4 and data["bones"][0] == [1, 0]
    frame = data["frames"][2]
    assert frame["index"] == 2 and frame["status"] == "tracked"
    np.testing.assert_allclose(np.array(frame["joints"]) / 1000, results[2].joints, atol=6e-4)
    points = np.array(frame["points"]).reshape(-1, 3) / 1000
    np.testing.assert_allclose(points, results[2].points, atol=6e-4)
    assert frame["labels"] == results[2].labels.tolist()
    assert data["frames"][1]["joints"] == [None] * 15 and data["frames"][1]["points"] == []


def test_viewer_subsamples_large_frames(tmp_path):
    _, results = _scene(1)
    path = write_viewer(results, tmp_path / "v.html", max_points=50)
    _, data, _ = _read_page(path)
    assert len(data["frames"][0]["labels"]) == 50


def _chromium() -> str | None:
    return shutil.which("chromium") or shutil.which("chromium-browser")


def _screenshot(url: str, shot: Path) -> np.ndarray:
    with tempfile.TemporaryDirectory() as profile:
        run = subprocess.run(
            [
                _chromium(),
                "--headless",
                "--no-sandbox",
                "--disable-gpu",
                "--disable-background-networking",
                "--disable-component-update",
                "--disable-sync",
                "--no-first-run",
                f"--user-data-dir={profile}",
                "--window-size=900,700",
                "--virtual-time-budget=3000",
                f"--screenshot={shot}",
                url,
            ],
            capture_output=True,
            timeout=90,
            check=False,
        )
    assert shot.exists(), run.stderr.decode(errors="replace")[-2000:]
    return iio.imread(shot)[..., :3][60:600]  # below the control bar, above the legend


def _width_of(view: np.ndarray) -> int:
    figure = np.flatnonzero((view.astype(int).sum(-1) > 200).any(axis=0))
    return int(figure.max() - figure.min())


@pytest.mark.skipif(_chromium() is None, reason="chromium is not installed")
def test_viewer_renders_in_headless_chromium(tmp_path):
    _, results = _scene(5)
    page = write_viewer(results, tmp_path / "view.html", start=4)
    view = _screenshot(page.resolve().as_uri(), tmp_path / "shot.png")
    assert _colour_present(view, (255, 255, 255), tol=10) > 100  # skeleton bones
    assert _colour_present(view, (255, 210, 0), tol=10) > 30  # joints
    assert _colour_present(view, HEAD, tol=10) > 5  # head points
    # the figure stands upright: head colour above the feet colours
    head_rows = np.flatnonzero((np.abs(view.astype(int) - HEAD) <= 10).all(-1).any(1))
    shank = np.abs(view.astype(int) - PART_COLOURS[12]) <= 10  # left shank: lavender
    shank_rows = np.flatnonzero(shank.all(-1).any(1))
    assert len(head_rows) and len(shank_rows) and head_rows.mean() < shank_rows.mean()
    # turned a quarter about the vertical axis, the T-posing figure is seen side on: narrow
    side = _screenshot(page.resolve().as_uri() + "#frame=0&yaw=1.5708", tmp_path / "side.png")
    front = _screenshot(page.resolve().as_uri() + "#frame=0", tmp_path / "front.png")
    assert _width_of(side) < 0.4 * _width_of(front)
