"""Speed of the depth renderer at the protocol's resolution, on one thread.

Two figures: the renderer alone on already posed vertices (camera frame), and a
whole synthetic frame (posing the body model from the joints, moving it into the
camera frame and rendering). Each is the median over repeats of the mean time per
frame over a batch of different poses of a motion clip.
"""

from __future__ import annotations

import platform
import time
from dataclasses import asdict, dataclass

import numpy as np

from posedrift._threads import one_thread
from posedrift._validation import check_scalar


@dataclass(frozen=True)
class RenderBenchmark:
    """Timings of :func:`bench_render`.

    Parameters
    ----------
    render_ms : float
        Median milliseconds per frame, rendering only (posed vertices given).
    pose_and_render_ms : float
        Median milliseconds per frame, posing the body included.
    render_repeats_ms, pose_and_render_repeats_ms : tuple of float
        The per-repeat means behind the medians.
    render_cpu_ms, pose_and_render_cpu_ms : float
        The same medians in process CPU time: on a shared, loaded machine they are
        closer to what an idle core would give than the wall-clock figures.
    frames : int
        Poses per repeat.
    width, height : int
        Image size.
    n_vertices, n_faces : int
        Mesh size.
    mean_person_pixels : float
        Mean number of person pixels per frame.
    background : bool
        Whether floor and wall were rendered too.
    cull_backfaces : bool
        Whether back faces were culled (as the sequence builder does).
    threads : str
        How the thread count was limited.
    machine : str
        Processor and Python.
    """

    render_ms: float
    pose_and_render_ms: float
    render_repeats_ms: tuple[float, ...]
    pose_and_render_repeats_ms: tuple[float, ...]
    render_cpu_ms: float
    pose_and_render_cpu_ms: float
    frames: int
    width: int
    height: int
    n_vertices: int
    n_faces: int
    mean_person_pixels: float
    background: bool
    cull_backfaces: bool
    threads: str
    machine: str

    @property
    def render_fps(self) -> float:
        """Frames per second, rendering only."""
        return 1000.0 / self.render_ms

    @property
    def pose_and_render_fps(self) -> float:
        """Frames per second, posing included."""
        return 1000.0 / self.pose_and_render_ms

    def to_dict(self) -> dict:
        """As JSON-ready values, with the frame rates."""
        out = asdict(self)
        out["render_fps"] = self.render_fps
        out["pose_and_render_fps"] = self.pose_and_render_fps
        return out


def bench_render(
    *,
    repeats: int = 7,
    frames: int = 30,
    background: bool = False,
    cull_backfaces: bool = True,
) -> RenderBenchmark:
    """Time the renderer on the default body in a procedural motion, one thread.

    Parameters
    ----------
    repeats : int
        Repeats; the medians are over them.
    frames : int
        Different poses (frames of :func:`procedural_motion` at 30 fps) per repeat.
    background : bool
        Render the floor and the back wall too.
    cull_backfaces : bool
        As the sequence builder renders (True).

    Returns
    -------
    RenderBenchmark
    """
    from posedrift.camera import camera_preset
    from posedrift.synthetic import BodyModel, Scene, procedural_motion, render
    from posedrift.synthetic._sequence import place_camera

    repeats = check_scalar(repeats, "repeats", low=1, include_low=True, integer=True)
    frames = check_scalar(frames, "frames", low=1, include_low=True, integer=True)
    intrinsics = camera_preset("kinect1-qvga")
    body = BodyModel.load_default()
    motion = procedural_motion(fps=30.0)
    n = min(frames, len(motion))
    # Spread the poses over the clip.
    picks = np.linspace(0, len(motion) - 1, n).round().astype(int)
    camera = place_camera(motion)
    scene = Scene(camera) if background else None
    extras = {k: np.asarray(v) for k, v in (motion.extras or {}).items()}
    joints = [np.asarray(motion.joints[t], dtype=float) for t in picks]
    extra_t = [{k: v[t] for k, v in extras.items()} for t in picks]
    posed = [camera.world_to_camera(body.pose(j, e)) for j, e in zip(joints, extra_t, strict=True)]
    faces, parts = np.asarray(body.faces), np.asarray(body.vertex_parts)

    def render_only() -> int:
        pixels = 0
        for vertices in posed:
            out = render(
                vertices,
                faces,
                intrinsics,
                vertex_parts=parts,
                scene=scene,
                cull_backfaces=cull_backfaces,
            )
            pixels += int(np.count_nonzero(out.labels))
        return pixels

    def pose_and_render() -> None:
        for j, e in zip(joints, extra_t, strict=True):
            vertices = camera.world_to_camera(body.pose(j, e))
            render(
                vertices,
                faces,
                intrinsics,
                vertex_parts=parts,
                scene=scene,
                cull_backfaces=cull_backfaces,
            )

    with one_thread() as threads:
        pixels = render_only()  # warm-up (caches, allocator)
        times_render, times_full, cpu_render, cpu_full = [], [], [], []
        for _ in range(repeats):
            start, cpu = time.perf_counter(), time.process_time()
            render_only()
            times_render.append(1000.0 * (time.perf_counter() - start) / n)
            cpu_render.append(1000.0 * (time.process_time() - cpu) / n)
            start, cpu = time.perf_counter(), time.process_time()
            pose_and_render()
            times_full.append(1000.0 * (time.perf_counter() - start) / n)
            cpu_full.append(1000.0 * (time.process_time() - cpu) / n)
    return RenderBenchmark(
        render_ms=float(np.median(times_render)),
        pose_and_render_ms=float(np.median(times_full)),
        render_repeats_ms=tuple(round(t, 3) for t in times_render),
        pose_and_render_repeats_ms=tuple(round(t, 3) for t in times_full),
        render_cpu_ms=float(np.median(cpu_render)),
        pose_and_render_cpu_ms=float(np.median(cpu_full)),
        frames=n,
        width=intrinsics.width,
        height=intrinsics.height,
        n_vertices=len(body.vertices),
        n_faces=len(faces),
        mean_person_pixels=pixels / n,
        background=background,
        cull_backfaces=cull_backfaces,
        threads=threads,
        machine=f"{platform.processor() or platform.machine()}, Python "
        f"{platform.python_version()}, NumPy {np.__version__}",
    )
