"""``posedrift view``: input checks, exit codes, preview animation."""

from __future__ import annotations

import imageio.v3 as iio
import numpy as np
from PIL import Image
from typer.testing import CliRunner

from posedrift.cli import app

runner = CliRunner()


def _folder(tmp_path, n=4):
    folder = tmp_path / "frames"
    folder.mkdir()
    for i in range(n):
        raw = np.zeros((240, 320), np.uint16)
        raw[50:200, 140:180] = 2500 + 100 * i
        Image.fromarray(raw).save(folder / f"{i:04d}.png")
    return folder


def test_view_reports_and_writes_a_preview(tmp_path):
    folder = _folder(tmp_path)
    result = runner.invoke(app, ["--quiet", "view", str(folder), "--out", str(tmp_path / "p.gif")])
    assert result.exit_code == 0, result.output
    assert "4 (4 readable, 0 unreadable)" in result.output
    assert "fx 285.63" in result.output and "2.500 - 2.800 m" in result.output
    movie = iio.imread(tmp_path / "p.gif", index=None)
    assert movie.shape == (4, 240, 320, 3)
    assert movie[0, 120, 160].max() > 100 and movie[0, 10, 10].max() == 0


def test_view_unreadable_frames_and_strict_exit_code(tmp_path):
    folder = _folder(tmp_path)
    (folder / "0002.png").write_bytes(b"garbage")
    result = runner.invoke(app, ["--quiet", "view", str(folder)])
    assert result.exit_code == 0
    assert "3 readable, 1 unreadable" in result.output
    assert "0002.png" in result.output  # stderr is mixed into output by the runner
    strict = runner.invoke(app, ["--quiet", "view", str(folder), "--strict"])
    assert strict.exit_code == 1


def test_view_bad_input_exit_code_2_names_the_problem(tmp_path):
    folder = _folder(tmp_path)
    cases = [
        (["view", str(folder), "--camera", "kinect7"], "Valid presets: kinect1-vga"),
        (["view", str(folder), "--intrinsics", "300,300,900,100"], "'cx' intrinsic"),
        (["view", str(folder), "--depth-scale", "cm"], "one of mm, tum, m"),
        (["view", str(tmp_path / "missing.npy")], "does not exist"),
    ]
    (tmp_path / "empty").mkdir()
    cases.append((["view", str(tmp_path / "empty")], "holds no .png depth frames"))
    np.savez(tmp_path / "k.npz", rgb=np.zeros((1, 2, 2)), ir=np.zeros((1, 2, 2)))
    cases.append((["view", str(tmp_path / "k.npz")], "Keys found: rgb, ir"))
    for args, message in cases:
        result = runner.invoke(app, ["--quiet", *args])
        assert result.exit_code == 2, (args, result.output)
        assert message in result.output, (args, result.output)
        assert "Traceback" not in result.output


def test_view_help_has_an_example():
    result = runner.invoke(app, ["view", "--help"])
    assert result.exit_code == 0 and "Example: posedrift view" in result.output
