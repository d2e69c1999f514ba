"""The synthetic evaluation protocol (``METHOD.md`` section 5): motion -> depth frames.

A motion clip drives the body model; a Kinect v1 QVGA camera about 2.8 m in
front of the person renders depth and the ground-truth part labels; the clip is
resampled to 30 fps and begins with a T-pose calibration frame.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, Any

import numpy as np

from posedrift._validation import check_rng, check_scalar
from posedrift.camera import CameraPose, DepthFrame, Intrinsics, camera_preset
from posedrift.evaluation._types import EvaluationSequence, Reference
from posedrift.skeleton import joint_angles, pelvis_centre
from posedrift.synthetic._noise import kinect_noise
from posedrift.synthetic._render import Scene, render

if TYPE_CHECKING:  # pragma: no cover
    from posedrift.synthetic._body import BodyModel
    from posedrift.synthetic._motion import Motion

logger = logging.getLogger(__name__)

DEFAULT_DISTANCE = 2.8
"""Metres from the camera to the person at frame 0 (``METHOD.md`` section 5)."""
DEFAULT_CAMERA_HEIGHT = 1.0
"""Metres above the floor: about a Kinect's height on a tripod, near the pelvis."""
DEFAULT_WALL_BEHIND = 1.5
"""Metres from the person's frame-0 position back to the wall, with ``background``."""


def place_camera(
    motion: Motion,
    *,
    distance: float = DEFAULT_DISTANCE,
    height: float | None = None,
    tilt: float = 0.0,
) -> CameraPose:
    """The protocol's camera: in front of the person at frame 0, looking at them level.

    The person faces +Z at frame 0 (the world convention of :class:`Motion`); the
    camera stands on the +Z side at ``distance`` from the frame-0 pelvis centre
    (measured horizontally), ``height`` above the floor, with its optical axis
    pointing toward -Z, horizontal or ``tilt`` degrees down. Facing the camera, the
    person's right appears on the image's left.

    Parameters
    ----------
    motion : Motion
        World frame: metres, +Y up, floor y = 0.
    distance : float
        Metres, horizontal.
    height : float, optional
        Camera height in metres; default :data:`DEFAULT_CAMERA_HEIGHT`.
    tilt : float
        Degrees the optical axis points below the horizontal, in (-90, 90): a camera
        mounted high looks down at the person (negative: up).

    Returns
    -------
    CameraPose

    Examples
    --------
    >>> from posedrift.synthetic import procedural_motion
    >>> pose = place_camera(procedural_motion(seconds=0.1), height=2.2, tilt=20.0)
    >>> axis = pose.rotation[2]  # the optical axis (camera +Z) in the world frame
    >>> round(float(np.degrees(np.arcsin(-axis[1]))), 6)
    20.0
    """
    distance = check_scalar(distance, "distance", low=0, caller="place_camera")
    if height is None:
        height = DEFAULT_CAMERA_HEIGHT
    height = check_scalar(height, "camera_height", caller="place_camera")
    tilt = check_scalar(tilt, "camera_tilt", low=-90.0, high=90.0, caller="place_camera")
    centre = pelvis_centre(np.asarray(motion.joints[0], dtype=float))
    eye = np.array([centre[0], height, centre[2] + distance])
    down = np.radians(tilt)
    target = eye + distance * np.array([0.0, -np.tan(down), -1.0])
    return CameraPose.look_at(eye, target)


def build_sequence(
    motion: Motion,
    *,
    body: BodyModel | None = None,
    intrinsics: Intrinsics | None = None,
    distance: float = DEFAULT_DISTANCE,
    camera_height: float | None = None,
    camera_tilt: float = 0.0,
    n_frames: int | None = None,
    fps: float = 30.0,
    noise: bool | Mapping[str, Any] = False,
    background: bool = False,
    shape: Mapping[str, Any] | None = None,
    stature: float | None = None,
    calibration: bool = True,
    in_place: bool = False,
    there_and_back: bool = False,
    facing: float = 0.0,
    rng: int | np.random.Generator | None = None,
    name: str | None = None,
    on_frame: Callable[[int, int], None] | None = None,
) -> EvaluationSequence:
    """Render a motion clip into an evaluation sequence: depth frames plus ground truth.

    Steps (``METHOD.md`` section 5): resample the clip to ``fps``; make frame 0 the
    T-pose calibration frame (:func:`with_calibration_pose` blends one in where the
    clip has none); keep the first ``n_frames``; place the camera in front of the
    person (:func:`place_camera`); pose the body per frame, render depth and part
    labels, optionally add Kinect-like noise; the reference holds the joints in the
    camera frame, their eight angles and the label images. A person who walks out
    of view still gives frames (with fewer or no person pixels).

    Parameters
    ----------
    motion : Motion
        The clip, world frame (metres, +Y up, floor y = 0, facing +Z at frame 0).
    body : BodyModel, optional
        Default :meth:`BodyModel.load_default`.
    intrinsics : Intrinsics, optional
        Default the ``kinect1-qvga`` preset (320 x 240, f = 285.63 px).
    distance : float
        Metres from the camera to the person at frame 0.
    camera_height : float, optional
        Metres above the floor (default 1.0).
    camera_tilt : float
        Degrees the camera looks down (negative: up); 0, level, is the protocol's.
    n_frames : int, optional
        Frames to keep from the start (frame 0 is the T-pose); None keeps the whole
        clip, ending on its last frame. A clip shorter than ``n_frames`` gives all
        its frames (logged).
    fps : float
        Frame rate to resample to.
    noise : bool or mapping
        Add :func:`kinect_noise`; a mapping passes its keyword arguments. Labels are
        zeroed where the noise removed the depth.
    background : bool
        Render a floor and a back wall (:class:`Scene`, the wall
        :data:`DEFAULT_WALL_BEHIND` metres behind the person); their pixels have depth
        and label 0.
    shape : mapping, optional
        Keyword arguments of ``body.with_shape`` (``girth``, ``morphs``). The body is
        posed on the clip's joints, so its bone lengths always follow the clip: use
        ``stature`` to make the person taller or shorter.
    stature : float, optional
        Scale the clip (joints and ground truth) uniformly about the floor point under
        the frame-0 pelvis so that the posed body at frame 0 (the T-pose) is this tall,
        in metres. None keeps the clip's own size.
    calibration : bool
        Apply :func:`with_calibration_pose` (default). False keeps the clip as is.
    in_place : bool
        Remove the pelvis's horizontal travel (a treadmill view): turns, jumps and
        squats stay, but a walking person stays at ``distance`` in view, as the
        protocol's person facing the camera at about 2.8 m. Angles do not change.
    there_and_back : bool
        Play the first half of the ``n_frames`` forward, then backward: frame
        ``n_frames - 1 - t`` repeats the pose of frame ``t``. The drift protocol: the
        last frames are the first ones' poses, so any difference in error between
        them is the method's drift, not a harder end of the clip.
    facing : float
        Degrees the person is turned from the camera at frame 0, to their left (the
        whole clip turned about the vertical through the frame-0 pelvis, before the
        camera is placed): 0 faces the camera (the protocol), 90 shows the right side,
        180 the back. Angles do not change.
    rng : int, numpy.random.Generator or None
        Seed or generator for the noise.
    name : str, optional
        Sequence name; default the motion's name.
    on_frame : callable, optional
        Called as ``on_frame(done, total)`` after each rendered frame (progress bars).

    Returns
    -------
    EvaluationSequence
        ``frames``: :class:`DepthFrame` float32 metres; ``reference``: joints
        ``(T, 15, 3)`` metres in the camera frame, angles ``(T, 8)`` degrees, labels
        ``(H, W)`` uint8 per frame (part index + 1, 0 background), kind "synthetic".

    Raises
    ------
    ValueError
        For a non-positive ``distance``, ``fps`` or ``n_frames``, or intrinsics that
        are not :class:`Intrinsics`.
    """
    from posedrift.synthetic._body import BodyModel
    from posedrift.synthetic._motion import with_calibration_pose

    where = "build_sequence"
    if intrinsics is None:
        intrinsics = camera_preset("kinect1-qvga")
    if not isinstance(intrinsics, Intrinsics):
        raise ValueError(
            f"The 'intrinsics' argument of {where} must be an Intrinsics. "
            f"Got {type(intrinsics).__name__} instead."
        )
    fps = check_scalar(fps, "fps", low=0, caller=where)
    if n_frames is not None:
        n_frames = check_scalar(n_frames, "n_frames", low=1, include_low=True, integer=True,
                                caller=where)  # fmt: skip
    noise_kwargs: dict[str, Any] | None = None
    if isinstance(noise, Mapping):
        noise_kwargs = dict(noise)
    elif noise:
        noise_kwargs = {}
    gen = check_rng(rng)

    if body is None:
        body = BodyModel.load_default()
    if shape:
        body = body.with_shape(**dict(shape))
    clip = motion if abs(motion.fps - fps) < 1e-9 else motion.resample(fps)
    if calibration:
        clip = with_calibration_pose(clip)
    if stature is not None:
        stature = check_scalar(stature, "stature", low=0.5, high=2.5, caller=where)
        clip = _scaled(clip, body, stature)
    if in_place:
        clip = _in_place(clip)
    facing = check_scalar(facing, "facing", low=-360.0, high=360.0, include_low=True,
                          include_high=True, caller=where)  # fmt: skip
    if facing != 0.0:
        clip = _turned(clip, facing)
    order = _frame_order(len(clip), n_frames, there_and_back)
    if n_frames is not None and len(order) < n_frames:
        logger.info(
            "clip %s has %d frames at %g fps; %d asked", clip.name, len(clip), fps, n_frames
        )
    count = len(order)

    camera = place_camera(clip, distance=distance, height=camera_height, tilt=camera_tilt)
    scene = None
    if background:
        centre = pelvis_centre(np.asarray(clip.joints[0], dtype=float))
        scene = Scene(camera, floor_y=0.0, wall_z=float(centre[2]) - DEFAULT_WALL_BEHIND)
    seq_name = name if name is not None else (getattr(clip, "name", "") or "synthetic")

    faces = np.asarray(body.faces)
    parts = np.asarray(body.vertex_parts)
    joints_world = np.asarray(clip.joints, dtype=float)[order]
    extras = {key: np.asarray(value)[order] for key, value in (clip.extras or {}).items()}
    frames: list[DepthFrame] = []
    labels: list[np.ndarray] = []
    for t in range(count):
        extras_t = {key: value[t] for key, value in extras.items()}
        vertices = body.pose(joints_world[t], extras_t)
        out = render(
            camera.world_to_camera(vertices),
            faces,
            intrinsics,
            vertex_parts=parts,
            scene=scene,
            cull_backfaces=True,
        )
        depth, label = out.depth, out.labels
        if noise_kwargs is not None:
            depth = kinect_noise(depth, rng=gen, **noise_kwargs)
            label = np.where(depth > 0, label, 0).astype(np.uint8)
        label.setflags(write=False)
        frames.append(
            DepthFrame(
                depth=depth, intrinsics=intrinsics, index=t, timestamp=t / fps, source=seq_name
            )
        )
        labels.append(label)
        if on_frame is not None:
            on_frame(t + 1, count)
    joints_cam = camera.world_to_camera(joints_world)
    reference = Reference(
        joints=joints_cam,
        angles=joint_angles(joints_cam),
        labels=tuple(labels),
        kind="synthetic",
    )
    return EvaluationSequence(name=seq_name, frames=tuple(frames), reference=reference, fps=fps)


def _frame_order(total: int, n_frames: int | None, there_and_back: bool) -> np.ndarray:
    """Which clip frame each sequence frame shows: the first ``n_frames``, or there and back.

    There and back: the first ``ceil(n_frames / 2)`` frames (the whole clip for None)
    forward, then the same backward, the turning frame once where ``n_frames`` is odd.
    """
    if not there_and_back:
        return np.arange(total if n_frames is None else min(n_frames, total))
    half = total if n_frames is None else min(-(-n_frames // 2), total)
    order = np.concatenate([np.arange(half), np.arange(half)[::-1]])
    if n_frames is not None and len(order) > n_frames:
        order = np.delete(order, half)
    return order


def _in_place(clip: Motion) -> Motion:
    """The clip with the pelvis's horizontal travel since frame 0 removed from every point."""
    from posedrift.synthetic._motion import Motion

    centres = pelvis_centre(np.asarray(clip.joints, dtype=float))
    travel = centres - centres[:1]
    travel[:, 1] = 0.0  # keep vertical motion: jumps, squats, climbing

    def shift(points: np.ndarray) -> np.ndarray:
        points = np.asarray(points, dtype=float)
        return points - (travel[:, None, :] if points.ndim == 3 else travel)

    return Motion(
        shift(clip.joints),
        {key: shift(value) for key, value in (clip.extras or {}).items()},
        clip.fps,
        clip.name,
        {**dict(getattr(clip, "meta", {}) or {}), "in_place": True},
    )


def _turned(clip: Motion, degrees: float) -> Motion:
    """The clip turned ``degrees`` to the person's left about the vertical through its
    frame-0 pelvis (a person facing +Z then faces ``(sin, 0, cos)`` of the angle)."""
    from posedrift.synthetic._motion import Motion, _yaw

    centre = pelvis_centre(np.asarray(clip.joints[0], dtype=float)) * [1.0, 0.0, 1.0]
    rotation = _yaw(np.radians(degrees))

    def turn(points: np.ndarray) -> np.ndarray:
        return (np.asarray(points, dtype=float) - centre) @ rotation.T + centre

    return Motion(
        turn(clip.joints),
        {key: turn(value) for key, value in (clip.extras or {}).items()},
        clip.fps,
        clip.name,
        {**dict(getattr(clip, "meta", {}) or {}), "facing": float(degrees)},
    )


def _scaled(clip: Motion, body: BodyModel, stature: float) -> Motion:
    """The clip scaled about the floor point under its frame-0 pelvis to a stature."""
    from posedrift.synthetic._motion import Motion

    extras0 = {key: np.asarray(value)[0] for key, value in (clip.extras or {}).items()}
    height = float(np.ptp(body.pose(np.asarray(clip.joints[0]), extras0)[:, 1]))
    factor = stature / height
    centre = pelvis_centre(np.asarray(clip.joints[0], dtype=float))
    origin = np.array([centre[0], 0.0, centre[2]])

    def scale(points: np.ndarray) -> np.ndarray:
        return origin + factor * (np.asarray(points, dtype=float) - origin)

    return Motion(
        scale(clip.joints),
        {key: scale(value) for key, value in (clip.extras or {}).items()},
        clip.fps,
        clip.name,
        {**dict(getattr(clip, "meta", {}) or {}), "scaled_to_stature_m": stature},
    )
