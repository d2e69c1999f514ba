"""An interactive 3-D view of points, labels and skeleton over time: one offline HTML file."""

from __future__ import annotations

import html
import json
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from posedrift.skeleton import JOINT_NAMES, JOINT_PARENTS, PART_COLOURS, PART_NAMES
from posedrift.tracking import FrameResult

DATA_ELEMENT_ID = "posedrift-data"
"""The id of the ``<script type="application/json">`` element that holds the data."""

_PAGE = """<!DOCTYPE html>
<html lang="en">
<head>
<meta charset="utf-8">
<meta name="viewport" content="width=device-width, initial-scale=1">
<title>__TITLE__</title>
<style>
body { margin: 0; background: #111; color: #ddd; font: 13px sans-serif; }
#bar { padding: 6px 10px; display: flex; gap: 10px; align-items: center; flex-wrap: wrap; }
#bar input[type=range] { flex: 1; min-width: 200px; }
#view { display: block; width: 100%; height: calc(100vh - 120px); cursor: grab; }
#legend span { display: inline-block; margin-right: 8px; }
#legend i { display: inline-block; width: 10px; height: 10px; margin-right: 3px; }
button { background: #333; color: #ddd; border: 1px solid #555; padding: 2px 10px; }
</style>
</head>
<body>
<div id="bar">
  <b>__TITLE__</b>
  <button id="play" type="button">play</button>
  <input id="slider" type="range" min="0" max="0" value="0" step="1">
  <span id="info"></span>
  <label><input id="showPoints" type="checkbox" checked> points</label>
  <label><input id="showSkeleton" type="checkbox" checked> skeleton</label>
  <button id="reset" type="button">front view</button>
</div>
<canvas id="view"></canvas>
<div id="bar2" style="padding: 2px 10px"><span id="legend"></span>
  <span style="color:#888">drag: rotate, wheel: zoom, arrows: step, space: play</span></div>
<script type="application/json" id="__DATA_ID__">__DATA__</script>
<script>
"use strict";
(function () {
  const data = JSON.parse(document.getElementById("__DATA_ID__").textContent);
  const canvas = document.getElementById("view");
  const ctx = canvas.getContext("2d");
  const slider = document.getElementById("slider");
  const info = document.getElementById("info");
  const playButton = document.getElementById("play");
  const showPoints = document.getElementById("showPoints");
  const showSkeleton = document.getElementById("showSkeleton");
  const n = data.frames.length;
  slider.max = Math.max(n - 1, 0);
  const legend = document.getElementById("legend");
  data.part_names.forEach(function (name, k) {
    const s = document.createElement("span");
    s.innerHTML = '<i style="background:' + data.colours[k] + '"></i>' + name;
    legend.appendChild(s);
  });
  let frame = 0, yaw = 0, pitch = 0, zoom = 1, playing = false, timer = null;
  const c = data.centre;
  function toView(x, y, z) {
    // camera frame (x right, y down, z forward) -> view (x right, y up, z to the viewer)
    let vx = x - c[0], vy = -(y - c[1]), vz = -(z - c[2]);
    const cy = Math.cos(yaw), sy = Math.sin(yaw);
    let ax = cy * vx + sy * vz, az = -sy * vx + cy * vz;
    const cp = Math.cos(pitch), sp = Math.sin(pitch);
    let ay = cp * vy - sp * az, bz = sp * vy + cp * az;
    const w = canvas.width, h = canvas.height;
    const f = zoom * 0.42 * Math.min(w, h) / data.extent;
    const persp = 4.0 / (4.0 - bz / data.extent);
    return [w / 2 + f * persp * ax, h / 2 - f * persp * ay, bz];
  }
  function line(a, b) {
    ctx.beginPath(); ctx.moveTo(a[0], a[1]); ctx.lineTo(b[0], b[1]); ctx.stroke();
  }
  function draw() {
    const w = canvas.clientWidth, h = canvas.clientHeight;
    if (canvas.width !== w || canvas.height !== h) { canvas.width = w; canvas.height = h; }
    ctx.fillStyle = "#111";
    ctx.fillRect(0, 0, canvas.width, canvas.height);
    if (!n) { info.textContent = "no frames"; return; }
    const fr = data.frames[frame];
    info.textContent = "frame " + fr.index + " / " + data.frames[n - 1].index + "  " + fr.status
      + (fr.time !== null ? "  t = " + fr.time.toFixed(2) + " s" : "")
      + "  " + fr.labels.length + " points";
    // floor grid under the skeleton for orientation
    ctx.strokeStyle = "#2a2a2a"; ctx.lineWidth = 1;
    for (let g = -2; g <= 2; g++) {
      line(toView(c[0] + g * 0.5, data.floor, c[2] - 1),
           toView(c[0] + g * 0.5, data.floor, c[2] + 1));
      line(toView(c[0] - 1, data.floor, c[2] + g * 0.5),
           toView(c[0] + 1, data.floor, c[2] + g * 0.5));
    }
    if (showPoints.checked) {
      const pts = [];
      for (let k = 0; k < fr.labels.length; k++) {
        const q = fr.points;
        const p = toView(q[3 * k] / 1000, q[3 * k + 1] / 1000, q[3 * k + 2] / 1000);
        pts.push([p[2], p[0], p[1], fr.labels[k]]);
      }
      pts.sort(function (a, b) { return a[0] - b[0]; });
      const r = Math.max(2, Math.min(canvas.width, canvas.height) / 180);
      for (const p of pts) {
        ctx.fillStyle = p[3] >= 0 && p[3] < data.colours.length ? data.colours[p[3]] : "#888";
        ctx.fillRect(p[1] - r / 2, p[2] - r / 2, r, r);
      }
    }
    if (showSkeleton.checked) {
      const js = fr.joints.map(function (j) {
        return j ? toView(j[0] / 1000, j[1] / 1000, j[2] / 1000) : null;
      });
      ctx.strokeStyle = "#fff"; ctx.lineWidth = 3;
      data.bones.forEach(function (b) {
        const a = js[b[0]], d = js[b[1]];
        if (a && d) { line(a, d); }
      });
      ctx.fillStyle = "#ffd200";
      js.forEach(function (j) {
        if (j) { ctx.beginPath(); ctx.arc(j[0], j[1], 4, 0, 2 * Math.PI); ctx.fill(); }
      });
    }
  }
  function setFrame(k) { frame = Math.max(0, Math.min(n - 1, k)); slider.value = frame; draw(); }
  function togglePlay() {
    playing = !playing; playButton.textContent = playing ? "pause" : "play";
    if (playing) {
      timer = setInterval(function () {
        setFrame(frame + 1 < n ? frame + 1 : 0);
      }, 1000 / data.fps);
    } else { clearInterval(timer); }
  }
  slider.addEventListener("input", function () { setFrame(parseInt(slider.value, 10)); });
  playButton.addEventListener("click", togglePlay);
  showPoints.addEventListener("change", draw);
  showSkeleton.addEventListener("change", draw);
  document.getElementById("reset").addEventListener("click", function () {
    yaw = 0; pitch = 0; zoom = 1; draw();
  });
  let drag = null;
  canvas.addEventListener("mousedown", function (e) {
    drag = [e.clientX, e.clientY]; canvas.style.cursor = "grabbing";
  });
  window.addEventListener("mouseup", function () { drag = null; canvas.style.cursor = "grab"; });
  window.addEventListener("mousemove", function (e) {
    if (!drag) return;
    yaw += (e.clientX - drag[0]) * 0.01;
    pitch = Math.max(-1.5, Math.min(1.5, pitch + (e.clientY - drag[1]) * 0.01));
    drag = [e.clientX, e.clientY]; draw();
  });
  canvas.addEventListener("wheel", function (e) {
    e.preventDefault();
    zoom = Math.max(0.2, Math.min(8, zoom * Math.exp(-e.deltaY * 0.001)));
    draw();
  }, { passive: false });
  window.addEventListener("keydown", function (e) {
    if (e.key === "ArrowRight") setFrame(frame + 1);
    else if (e.key === "ArrowLeft") setFrame(frame - 1);
    else if (e.key === " ") { e.preventDefault(); togglePlay(); }
  });
  window.addEventListener("resize", draw);
  // optional initial view from the address: viewer.html#frame=10&yaw=1.2&pitch=0.3&zoom=2
  const view = {};
  window.location.hash.replace(/^#/, "").split("&").forEach(function (kv) {
    const pair = kv.split("=");
    if (pair.length === 2 && isFinite(parseFloat(pair[1]))) view[pair[0]] = parseFloat(pair[1]);
  });
  if (view.yaw !== undefined) yaw = view.yaw;
  if (view.pitch !== undefined) pitch = Math.max(-1.5, Math.min(1.5, view.pitch));
  if (view.zoom !== undefined) zoom = Math.max(0.2, Math.min(8, view.zoom));
  const start = view.frame !== undefined ? view.frame : (data.start !== undefined ? data.start : 0);
  setFrame(Math.round(start));
})();
</script>
</body>
</html>
"""


def _hex(colour: tuple[int, int, int]) -> str:
    return "#{:02x}{:02x}{:02x}".format(*colour)


def viewer_data(
    results: Sequence[FrameResult],
    *,
    title: str = "posedrift",
    fps: float = 15.0,
    max_points: int = 2000,
    rng: int | np.random.Generator | None = 0,
) -> dict:
    """The data the viewer page embeds (also handy for tests).

    Points and joints are whole millimetres in the camera frame; ``labels`` are
    part indices; unknown joints are null.
    """
    from posedrift._validation import check_rng

    generator = check_rng(rng)
    frames = []
    known = []
    for r in results:
        points = np.asarray(r.points, dtype=float).reshape(-1, 3)
        labels = np.asarray(r.labels).reshape(-1)
        if len(labels) != len(points):
            labels = np.full(len(points), -1)
        finite = np.isfinite(points).all(axis=1)
        points, labels = points[finite], labels[finite]
        if len(points) > max_points:
            keep = np.sort(generator.choice(len(points), max_points, replace=False))
            points, labels = points[keep], labels[keep]
        joints = [
            [round(float(v) * 1000) for v in j] if np.isfinite(j).all() else None for j in r.joints
        ]
        known.append(r.joints[np.isfinite(r.joints).all(axis=1)])
        if len(points):
            known.append(points)
        frames.append(
            {
                "index": int(r.index),
                "status": r.status.value,
                "time": None if r.timestamp is None else float(r.timestamp),
                "points": [int(v) for v in np.rint(points * 1000).reshape(-1)],
                "labels": [int(v) for v in labels],
                "joints": joints,
            }
        )
    everything = np.concatenate(known) if known else np.zeros((0, 3))
    if len(everything):
        centre = np.median(everything, axis=0)
        extent = float(np.percentile(np.linalg.norm(everything - centre, axis=1), 98))
        floor = float(np.percentile(everything[:, 1], 99.5))
    else:
        centre, extent, floor = np.array([0.0, 0.0, 2.8]), 1.0, 0.9
    return {
        "title": title,
        "fps": float(fps),
        "centre": [float(v) for v in centre],
        "extent": max(extent, 0.2),
        "floor": floor,
        "joint_names": list(JOINT_NAMES),
        "part_names": list(PART_NAMES),
        "colours": [_hex(c) for c in PART_COLOURS],
        "bones": [[p, j] for j, p in enumerate(JOINT_PARENTS) if p >= 0],
        "frames": frames,
    }


def write_viewer(
    results: Sequence[FrameResult],
    path: str | Path,
    *,
    title: str = "posedrift: recovered pose",
    fps: float = 15.0,
    max_points: int = 2000,
    start: int = 0,
) -> Path:
    """Write a self-contained HTML page: labelled points and skeleton in 3-D over time.

    The page works offline in any browser (no network, no libraries: a small
    2-D-canvas projection script is inlined). A slider picks the frame, play
    animates at ``fps``, dragging rotates the view, the wheel zooms. The address
    may set the first view: ``viewer.html#frame=10&yaw=1.57&pitch=0.3&zoom=1.5``
    (radians; yaw turns about the vertical axis).

    Parameters
    ----------
    results : sequence of FrameResult
    path : str or Path
        The ``.html`` file.
    title : str
    fps : float
        Playback rate.
    max_points : int
        Points kept per frame (a random subset beyond it), to bound the file size.
    start : int
        Position in ``results`` of the frame shown when the page opens.

    Returns
    -------
    Path

    Examples
    --------
    >>> import numpy as np, tempfile, pathlib
    >>> from posedrift.skeleton import t_pose_joints
    >>> from posedrift.tracking import FrameResult, FrameStatus
    >>> joints = t_pose_joints(1.75) * [1, -1, -1] + [0, 0.9, 2.8]
    >>> result = FrameResult(0, FrameStatus.TRACKED, joints, np.ones(15))
    >>> page = write_viewer([result], pathlib.Path(tempfile.mkdtemp()) / "view.html")
    >>> "http" in page.read_text()
    False
    """
    results = list(results)
    data = viewer_data(results, title=title, fps=fps, max_points=max_points)
    data["start"] = int(min(max(start, 0), max(len(results) - 1, 0)))
    text = json.dumps(data, separators=(",", ":"), allow_nan=False)
    text = text.replace("<", "\\u003c")  # nothing in the data can close the script element
    page = (
        _PAGE.replace("__TITLE__", html.escape(title))
        .replace("__DATA_ID__", DATA_ELEMENT_ID)
        .replace("__DATA__", text)
    )
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(page, encoding="utf-8")
    return path
