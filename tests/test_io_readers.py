"""Depth readers: PNG folders, NumPy stacks, UTD-MHAD .mat, RealSense recordings."""

from __future__ import annotations

import logging
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from posedrift.camera import DepthFrame, Intrinsics
from posedrift.io import UnreadableFrame, open_depth_source, resolve_depth_scale


def _depth_stack(n: int = 4, shape: tuple[int, int] = (240, 320)) -> np.ndarray:
    """uint16 millimetres: a 'person' box at 2.8 m that moves right one pixel per frame."""
    stack = np.zeros((n, *shape), dtype=np.uint16)
    for i in range(n):
        stack[i, 60:200, 140 + i : 180 + i] = 2800 + i
    return stack


def _write_png_folder(folder: Path, stack: np.ndarray) -> list[Path]:
    folder.mkdir(parents=True, exist_ok=True)
    paths = []
    for i, frame in enumerate(stack):
        path = folder / f"{i:06d}.png"
        Image.fromarray(frame).save(path)
        paths.append(path)
    return paths


# -- PNG folders ------------------------------------------------------------------------------


def test_png_folder_round_trip_in_metres(tmp_path):
    stack = _depth_stack()
    _write_png_folder(tmp_path / "d", stack)
    source = open_depth_source(tmp_path / "d", camera="kinect1-qvga")
    frames = list(source)
    assert len(source) == len(frames) == 4
    assert all(isinstance(f, DepthFrame) for f in frames)
    for i, frame in enumerate(frames):
        np.testing.assert_allclose(frame.depth, stack[i] / 1000.0, atol=1e-6)
        assert frame.index == i
        assert frame.timestamp == pytest.approx(i / 30.0)
        assert frame.source.endswith(f"{i:06d}.png")
    assert source.intrinsics.fx == pytest.approx(285.63)


def test_png_folder_tum_scale_fps_and_natural_order(tmp_path):
    stack = _depth_stack(3)
    folder = tmp_path / "tum"
    folder.mkdir()
    for i, name in enumerate(["2", "10", "1"]):  # natural order: 1, 2, 10
        Image.fromarray(stack[i] * 5 // 2).save(folder / f"{name}.png")
    source = open_depth_source(folder, depth_scale="tum", fps=10)
    frames = list(source)
    assert [Path(f.source).name for f in frames] == ["1.png", "2.png", "10.png"]
    # frame '1.png' holds stack[2] * 2.5 in 1/5000 m units -> stack[2] / 2000 m
    np.testing.assert_allclose(frames[0].depth, stack[2] * 5 // 2 / 5000.0, atol=1e-6)
    assert frames[2].timestamp == pytest.approx(0.2)


def test_png_timestamps_from_tum_file_names(tmp_path):
    stack = _depth_stack(3)
    folder = tmp_path / "names"
    folder.mkdir()
    for name, frame in zip(
        ["1305031102.160407", "1305031102.194330", "1305031102.226738"], stack, strict=True
    ):
        Image.fromarray(frame).save(folder / f"{name}.png")
    stamps = [f.timestamp for f in open_depth_source(folder, depth_scale=5000)]
    np.testing.assert_allclose(stamps, [0.0, 0.033923, 0.066331], atol=1e-6)


def test_synth_layout_depth_subfolder(tmp_path):
    _write_png_folder(tmp_path / "out" / "depth", _depth_stack(2))
    source = open_depth_source(tmp_path / "out")
    assert len(source) == 2 and source.path.name == "depth"


def test_synth_folder_reads_depth_not_the_contact_sheet_and_its_camera(tmp_path):
    """A ``posedrift synth`` folder: an 8-bit RGB contact sheet on top, frames in depth/."""
    import json

    root = tmp_path / "s1"
    stack = _depth_stack(3, (480, 640))
    _write_png_folder(root / "depth", stack)
    Image.fromarray(np.zeros((40, 60, 3), np.uint8)).save(root / "contact_sheet.png")
    d435 = {"fx": 385.0, "fy": 385.0, "cx": 320.0, "cy": 240.0, "width": 640, "height": 480}
    (root / "ground_truth.json").write_text(json.dumps({"intrinsics": d435, "fps": 15.0}))
    source = open_depth_source(root)
    assert source.path == root / "depth" and len(source) == 3
    # the camera synth rendered with (d435), not the 640 x 480 default (kinect1-vga, 571.26)
    assert source.intrinsics == Intrinsics(**d435)
    frames = list(source)
    assert all(isinstance(f, DepthFrame) for f in frames)
    np.testing.assert_allclose(frames[2].depth, stack[2] / 1000.0, atol=1e-6)
    assert frames[2].depth[100, 150] == pytest.approx(2.802)  # metres
    np.testing.assert_allclose([f.timestamp for f in frames], [0.0, 1 / 15, 2 / 15])
    # an explicit camera still wins over ground_truth.json
    assert open_depth_source(root, camera="kinect1-vga").intrinsics.fx == pytest.approx(571.26)
    # a malformed ground_truth.json is ignored: the frames are still read, camera by size
    (root / "ground_truth.json").write_text("{not json")
    fallback = open_depth_source(root)
    assert len(fallback) == 3 and fallback.intrinsics.fx == pytest.approx(571.26)


def test_default_intrinsics_by_size_logs_notice(tmp_path, caplog):
    np.save(tmp_path / "vga.npy", _depth_stack(1, (480, 640)))
    with caplog.at_level(logging.INFO, logger="posedrift.io"):
        source = open_depth_source(tmp_path / "vga.npy")
    assert source.intrinsics.width == 640 and source.intrinsics.fx == pytest.approx(571.26)
    assert "kinect1-vga" in caplog.text
    np.save(tmp_path / "k2.npy", _depth_stack(1, (424, 512)))
    assert open_depth_source(tmp_path / "k2.npy").intrinsics.width == 512


def test_corrupt_png_yields_unreadable_frame_and_goes_on(tmp_path):
    paths = _write_png_folder(tmp_path / "d", _depth_stack(4))
    data = paths[1].read_bytes()
    paths[1].write_bytes(data[: len(data) // 2])  # truncated
    paths[2].write_bytes(b"not a png at all")
    frames = list(open_depth_source(tmp_path / "d", camera="kinect1-qvga"))
    assert [type(f).__name__ for f in frames] == [
        "DepthFrame",
        "UnreadableFrame",
        "UnreadableFrame",
        "DepthFrame",
    ]
    bad = frames[1]
    assert isinstance(bad, UnreadableFrame)
    assert bad.index == 1 and bad.source.endswith("000001.png")
    assert "000002.png" in str(frames[2]) and "frame 2" in str(frames[2])
    assert frames[3].index == 3


def test_mismatched_and_8bit_frames_are_reported_per_frame(tmp_path):
    paths = _write_png_folder(tmp_path / "d", _depth_stack(3))
    Image.fromarray(np.zeros((120, 160), np.uint16)).save(paths[1])
    Image.fromarray(np.zeros((240, 320), np.uint8)).save(paths[2])
    frames = list(open_depth_source(tmp_path / "d"))
    assert isinstance(frames[0], DepthFrame)
    assert isinstance(frames[1], UnreadableFrame) and "160 x 120" in frames[1].message
    assert "320 x 240" in frames[1].message
    assert isinstance(frames[2], UnreadableFrame) and "8-bit" in frames[2].message


def test_all_8bit_folder_is_an_error_naming_the_file(tmp_path):
    folder = tmp_path / "rgb"
    folder.mkdir()
    Image.fromarray(np.zeros((240, 320, 3), np.uint8)).save(folder / "a.png")
    with pytest.raises(ValueError, match=r"a\.png is a 8-bit RGB PNG.*16-bit greyscale"):
        open_depth_source(folder)


def test_folder_of_unreadable_pngs_is_an_error(tmp_path):
    folder = tmp_path / "junk"
    folder.mkdir()
    for name in ("a.png", "b.png"):
        (folder / name).write_bytes(b"junk")
    with pytest.raises(ValueError, match=r"None of the 2 PNG files in .*junk' is readable"):
        open_depth_source(folder)


def test_empty_folder_is_an_error(tmp_path):
    (tmp_path / "empty").mkdir()
    with pytest.raises(ValueError, match=r"empty.*holds no \.png depth frames"):
        open_depth_source(tmp_path / "empty")


# -- options ----------------------------------------------------------------------------------


def test_unknown_camera_lists_presets(tmp_path):
    np.save(tmp_path / "s.npy", _depth_stack(1))
    with pytest.raises(ValueError, match=r"Unknown camera preset 'kinect9'.*kinect1-qvga.*d435"):
        open_depth_source(tmp_path / "s.npy", camera="kinect9")


def test_camera_of_the_wrong_size_names_sizes(tmp_path):
    np.save(tmp_path / "s.npy", _depth_stack(1))
    with pytest.raises(ValueError, match=r"'d435' is 640 x 480 .* 320 x 240 frames"):
        open_depth_source(tmp_path / "s.npy", camera="d435")


def test_explicit_intrinsics_string_and_bad_principal_point(tmp_path):
    np.save(tmp_path / "s.npy", _depth_stack(1))
    source = open_depth_source(tmp_path / "s.npy", intrinsics="300,301,161,119")
    assert source.intrinsics == Intrinsics(300, 301, 161, 119, 320, 240)
    with pytest.raises(ValueError, match=r"'cx' intrinsic \(principal point\) must lie inside"):
        open_depth_source(tmp_path / "s.npy", intrinsics="300,300,500,120")
    with pytest.raises(ValueError, match="not both"):
        open_depth_source(tmp_path / "s.npy", intrinsics="300,300,160,120", camera="kinect2")


def test_unknown_size_asks_for_camera(tmp_path):
    np.save(tmp_path / "odd.npy", _depth_stack(1, (100, 100)))
    with pytest.raises(ValueError, match=r"100 x 100.*--camera NAME \(one of kinect1-vga"):
        open_depth_source(tmp_path / "odd.npy")


def test_depth_scale_names_and_errors():
    assert resolve_depth_scale("mm", default=1.0) == 1000.0
    assert resolve_depth_scale("5000", default=1.0) == 5000.0
    with pytest.raises(ValueError, match=r"'depth_scale'.*Got -3"):
        resolve_depth_scale(-3, default=1.0)
    with pytest.raises(ValueError, match=r"one of mm, tum, m\. Got 'cm'"):
        resolve_depth_scale("cm", default=1.0)


def test_missing_and_unknown_inputs(tmp_path):
    with pytest.raises(FileNotFoundError, match="does not exist"):
        open_depth_source(tmp_path / "nope.npy")
    (tmp_path / "x.txt").write_text("hi")
    with pytest.raises(ValueError, match=r"Cannot tell the format.*\.npz, \.mat"):
        open_depth_source(tmp_path / "x.txt")


# -- NumPy and MATLAB stacks ------------------------------------------------------------------


def test_npy_float_metres_and_single_frame(tmp_path):
    metres = _depth_stack(2).astype(np.float32) / 1000.0
    np.save(tmp_path / "m.npy", metres)
    frames = list(open_depth_source(tmp_path / "m.npy"))
    np.testing.assert_allclose(frames[1].depth, metres[1])
    np.save(tmp_path / "one.npy", _depth_stack(1)[0])
    assert len(open_depth_source(tmp_path / "one.npy")) == 1


def test_npz_with_intrinsics_and_timestamps(tmp_path):
    stack = _depth_stack(3)
    np.savez(
        tmp_path / "s.npz",
        depth=stack,
        intrinsics=np.array([290.0, 290.0, 150.0, 110.0]),
        timestamps=np.array([0.0, 0.05, 0.1]),
    )
    source = open_depth_source(tmp_path / "s.npz")
    assert source.intrinsics == Intrinsics(290.0, 290.0, 150.0, 110.0, 320, 240)
    frames = list(source)
    assert [f.timestamp for f in frames] == [0.0, 0.05, 0.1]
    np.testing.assert_allclose(frames[2].depth, stack[2] / 1000.0, atol=1e-6)
    np.savez(tmp_path / "single.npz", whatever=stack)
    assert len(open_depth_source(tmp_path / "single.npz")) == 3


def test_npz_without_depth_key_lists_keys(tmp_path):
    np.savez(tmp_path / "bad.npz", rgb=np.zeros((2, 4, 4)), mask=np.zeros((2, 4, 4)))
    with pytest.raises(ValueError, match=r"bad\.npz.*'depth'.*Keys found: rgb, mask"):
        open_depth_source(tmp_path / "bad.npz")


def test_bad_stack_shape(tmp_path):
    np.save(tmp_path / "v.npy", np.zeros(5))
    with pytest.raises(ValueError, match=r"v\.npy.*\(frames, height, width\)"):
        open_depth_source(tmp_path / "v.npy")


def test_mat_in_utd_layout(tmp_path):
    from scipy.io import savemat

    stack = _depth_stack(3)
    savemat(tmp_path / "a1_s1_t1_depth.mat", {"d_depth": np.moveaxis(stack, 0, -1)})
    source = open_depth_source(tmp_path / "a1_s1_t1_depth.mat")
    frames = list(source)
    assert len(frames) == 3 and source.unmirror  # UTD-MHAD images are mirrored
    np.testing.assert_allclose(frames[1].depth, stack[1][:, ::-1] / 1000.0, atol=1e-6)
    assert source.intrinsics.cx == 319 - 160.0
    raw = open_depth_source(tmp_path / "a1_s1_t1_depth.mat", unmirror=False)
    np.testing.assert_allclose(next(iter(raw)).depth, stack[0] / 1000.0, atol=1e-6)
    assert raw.intrinsics.cx == 160.0
    savemat(tmp_path / "other.mat", {"d_skel": np.zeros((20, 3, 2))})
    with pytest.raises(ValueError, match=r"other\.mat.*'d_depth'.*Variables found: d_skel"):
        open_depth_source(tmp_path / "other.mat")


def test_truncated_mat_names_the_file(tmp_path):
    from scipy.io import savemat

    whole = tmp_path / "whole.mat"
    savemat(whole, {"d_depth": np.moveaxis(_depth_stack(3), 0, -1)})
    data = whole.read_bytes()
    for keep in (2000, 100):  # header readable but data cut / header cut
        cut = tmp_path / f"a1_s1_t1_cut{keep}.mat"
        cut.write_bytes(data[:keep])
        with pytest.raises(ValueError, match=rf"MATLAB file '.*a1_s1_t1_cut{keep}\.mat'"):
            open_depth_source(cut)


def test_unmirror_mirrors_the_geometry(tmp_path):
    from posedrift.camera import backproject

    stack = _depth_stack(1)
    np.save(tmp_path / "s.npy", stack)
    plain = next(iter(open_depth_source(tmp_path / "s.npy", intrinsics="280,285,150,118")))
    flipped_source = open_depth_source(
        tmp_path / "s.npy", intrinsics="280,285,150,118", unmirror=True
    )
    flipped = next(iter(flipped_source))
    assert flipped_source.intrinsics.cx == 319 - 150.0
    a, _ = backproject(plain.depth, plain.intrinsics)
    b, _ = backproject(flipped.depth, flipped.intrinsics)
    # the flipped frame back-projects to the mirror image (x -> -x) of the raw one
    key = np.lexsort(a.T)
    mirrored = b * [-1.0, 1.0, 1.0]
    np.testing.assert_allclose(mirrored[np.lexsort(mirrored.T)], a[key], atol=1e-9)


@pytest.mark.data
def test_real_utd_sequence_matches_the_evaluation_loader(utd_dir):
    from posedrift.evaluation import load_utd_sequence

    depth = utd_dir / "Depth" / "a5_s2_t1_depth.mat"
    skeleton = utd_dir / "Skeleton" / "a5_s2_t1_skeleton.mat"
    if not (depth.exists() and skeleton.exists()):
        pytest.skip(f"{depth} not found")
    sequence = load_utd_sequence(depth, skeleton)
    source = open_depth_source(depth)
    frames = list(source)
    assert source.intrinsics == sequence.frames[0].intrinsics
    assert len(frames) == len(sequence.frames)
    for ours, theirs in zip(frames, sequence.frames, strict=True):
        np.testing.assert_array_equal(ours.depth, theirs.depth)


@pytest.mark.data
def test_real_utd_sequence(utd_dir):
    path = utd_dir / "Depth" / "a27_s1_t1_depth.mat"
    if not path.exists():
        pytest.skip(f"{path} not found")
    source = open_depth_source(path)
    assert source.intrinsics.shape == (240, 320) and len(source) > 30
    frame = next(iter(source))
    person = frame.depth[frame.depth > 0]
    assert 1.5 < np.median(person) < 4.0  # the person stands 2.3-3.2 m away
    assert 0.01 < person.size / frame.depth.size < 0.5


# -- RealSense --------------------------------------------------------------------------------


def _need_realsense():
    """Skip where pyrealsense2 is absent or cannot load (its wheel needs libusb-1.0)."""
    return pytest.importorskip(
        "pyrealsense2",
        reason="pyrealsense2 is not installed or cannot load (apt-get install libusb-1.0-0)",
        exc_type=ImportError,
    )


_RECORDER = """\
import sys, time
import numpy as np
import pyrealsense2 as rs


def record(path, stack, stream):
    height, width = stack.shape[1:]
    device = rs.software_device()
    sensor = device.add_sensor("Depth" if stream == "depth" else "Color")
    intr = rs.intrinsics()
    intr.width, intr.height, intr.ppx, intr.ppy, intr.fx, intr.fy = width, height, 31, 23, 52, 53
    intr.model = rs.distortion.none
    intr.coeffs = [0.0] * 5
    vs = rs.video_stream()
    vs.type = rs.stream.depth if stream == "depth" else rs.stream.color
    vs.index, vs.uid, vs.width, vs.height, vs.fps = 0, 0, width, height, 30
    vs.bpp = 2 if stream == "depth" else 3
    vs.fmt = rs.format.z16 if stream == "depth" else rs.format.rgb8
    vs.intrinsics = intr
    profile = sensor.add_video_stream(vs)
    if stream == "depth":
        sensor.add_read_only_option(rs.option.depth_units, 0.001)
    recorder = rs.recorder(str(path), device)
    queue = rs.frame_queue(10)
    sensor.open(profile)
    sensor.start(queue)
    for i, image in enumerate(stack):
        frame = rs.software_video_frame()
        frame.pixels = image if stream == "depth" else np.repeat(image[..., None], 3, -1)
        frame.bpp = vs.bpp
        frame.stride = width * vs.bpp
        frame.timestamp = i * 1000.0 / 30.0
        frame.domain = rs.timestamp_domain.hardware_clock
        frame.frame_number = i
        frame.profile = profile.as_video_stream_profile()
        if stream == "depth":
            frame.depth_units = 0.001
        sensor.on_video_frame(frame)
        time.sleep(0.02)
    sensor.stop()
    sensor.close()
    del recorder


record(sys.argv[1], np.load(sys.argv[2]), sys.argv[3])
"""
"""A child script that records a stack through librealsense's software device."""


def _record(path: Path, stack: np.ndarray, *, stream: str = "depth") -> None:
    """Record ``stack`` through librealsense's software device (a ROS2 .db3 rosbag).

    The recording runs in a child process: librealsense's recorder can crash while it
    tears down its threads on a loaded machine, which must not take the test run with
    it. A crashed recording (killed by a signal) is retried twice.
    """
    _need_realsense()
    frames = path.with_suffix(".npy")
    np.save(frames, stack)
    for _attempt in range(3):
        path.unlink(missing_ok=True)
        done = subprocess.run(
            [sys.executable, "-c", _RECORDER, str(path), str(frames), stream],
            capture_output=True,
            text=True,
            timeout=60,
        )
        if done.returncode >= 0:
            break
    assert done.returncode == 0, done.stderr
    assert path.exists(), f"librealsense wrote no recording: {done.stderr}"


def test_realsense_recording_round_trip(tmp_path):
    _need_realsense()
    stack = np.zeros((5, 48, 64), np.uint16)
    for i in range(5):
        stack[i, 10:40, 20 + i : 40 + i] = 2800 + 10 * i
    _record(tmp_path / "rec.db3", stack)
    source = open_depth_source(tmp_path / "rec.db3")
    assert source.intrinsics == Intrinsics(52.0, 53.0, 31.0, 23.0, 64, 48)
    assert source.depth_scale == pytest.approx(1000.0)
    frames = [f for f in source if isinstance(f, DepthFrame)]
    assert len(frames) >= 3  # the recorder may drop a frame at the start or end
    assert len(source) == len(frames)
    # each recorded frame is identified by its depth value 2.8 m + 1 cm * i
    recorded = [round((float(f.depth.max()) - 2.8) * 100) for f in frames]
    assert recorded == sorted(set(recorded))
    for frame, i in zip(frames, recorded, strict=True):
        np.testing.assert_allclose(frame.depth, stack[i] / 1000.0, atol=1e-6)
        assert frame.timestamp == pytest.approx((i - recorded[0]) / 30.0, abs=1e-4)
    # a camera preset of the wrong size is refused, naming the recording's size
    with pytest.raises(ValueError, match="64 x 48 frames"):
        open_depth_source(tmp_path / "rec.db3", camera="d435")


def test_realsense_without_depth_stream(tmp_path):
    _need_realsense()
    _record(tmp_path / "colour.db3", np.zeros((3, 48, 64), np.uint8), stream="color")
    with pytest.raises(ValueError, match=r"colour\.db3' has no depth stream. Streams found: color"):
        open_depth_source(tmp_path / "colour.db3")


def test_realsense_that_cannot_load_says_why(tmp_path, monkeypatch):
    """pyrealsense2 installed without its system library: the error says what to install."""
    fake = tmp_path / "site" / "pyrealsense2"
    fake.mkdir(parents=True)
    (fake / "__init__.py").write_text(
        "raise ImportError('libusb-1.0.so.0: cannot open shared object file')\n"
    )
    monkeypatch.syspath_prepend(str(tmp_path / "site"))
    monkeypatch.delitem(sys.modules, "pyrealsense2", raising=False)
    (tmp_path / "rec.bag").write_bytes(b"")
    with pytest.raises(ImportError, match=r"cannot load \(libusb.*apt-get install libusb-1.0-0"):
        open_depth_source(tmp_path / "rec.bag")


def test_realsense_unplayable_bag_names_the_file(tmp_path):
    _need_realsense()
    (tmp_path / "broken.bag").write_bytes(b"#ROSBAG V2.0\nnot really")
    with pytest.raises(ValueError, match=r"Cannot play back the RealSense recording .*broken\.bag"):
        open_depth_source(tmp_path / "broken.bag")


_DYING_PLAYER = """
import os, pickle, sys
import numpy as np
out = sys.stdout.buffer
if sys.argv[1] == "describe":
    stream = {"intrinsics": (52.0, 53.0, 31.0, 23.0, 64, 48), "width": 64, "height": 48,
              "fps": 30, "units": 0.001}
    pickle.dump(("stream", stream), out)
    pickle.dump(("end",), out)
    sys.exit(0)
for i in range(2):
    pickle.dump(("frame", i, i / 30.0, np.full((48, 64), 2800, np.uint16), ""), out)
out.flush()
sys.stderr.write("terminate called without an active exception\\n")
sys.stderr.flush()
os.abort()
"""


def test_realsense_playback_that_dies_keeps_its_frames(tmp_path, monkeypatch):
    """librealsense aborting mid-recording costs only the frames it had not delivered."""
    _need_realsense()
    from posedrift.io import _realsense

    def dying(path, mode):
        return [sys.executable, "-c", _DYING_PLAYER, mode]

    monkeypatch.setattr(_realsense, "_child_command", dying)
    (tmp_path / "any.bag").write_bytes(b"")  # the stand-in player never opens it
    source = open_depth_source(tmp_path / "any.bag")
    items = list(source)
    assert [type(item) for item in items] == [DepthFrame, DepthFrame, UnreadableFrame]
    np.testing.assert_allclose(items[1].depth, 2.8)
    assert items[2].index == 2
    assert items[2].source.endswith("any.bag#2")
    assert "SIGABRT" in items[2].message
    assert "terminate called without an active exception" in items[2].message
    assert len(source) == 3
