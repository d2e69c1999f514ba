"""The tracker: depth frames in, a pose per frame out (the paper's Sections 3.1-3.4).

Per frame: segment the person; back-project (Eq. 1); downsample to about 400
points; register the previous frame's labelled points onto them (nonrigid CPD,
Algorithm 1, warm-started); carry the labels over through the posterior; fuse in
the per-pixel part probabilities at the points' pixels (a product of experts,
beyond the paper: it stops the labels drifting; ``appearance_weight=0`` is the
paper's pure tracking); relabel by geodesic reach from the part joints
(Algorithm 2); mean-shift part modes; fit the skeleton with the calibrated bone
lengths; judge the track's health, and re-initialize from the per-pixel labels
when it is lost. The per-pixel labels come from the body-part nets (beyond the paper:
a frontal one, and one for a person turned away that the track's own facing calls in;
``part_net="none"`` gives the body-part forest's), the joint votes from the forest.
"""

from __future__ import annotations

import bisect
import copy
import math
import time
import warnings
from collections import deque
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from scipy.spatial.distance import cdist

from posedrift._stats import median
from posedrift._threads import blas_limited
from posedrift._validation import check_rng, check_scalar
from posedrift.camera import DepthFrame, Intrinsics, backproject, project
from posedrift.camera._frame import MAX_PERSON_DEPTH
from posedrift.labelling._features import CheckedPixels
from posedrift.labelling._relabel import geodesic_graph, merge_islands, relabel, row_shares
from posedrift.points._downsample import downsample_checked
from posedrift.points._segment import BackgroundModel, segment_person
from posedrift.skeleton._angles import facing_yaw
from posedrift.skeleton._definitions import PART_INDEX
from posedrift.skeleton._fit import (
    VOTED_JOINTS,
    SkeletonFit,
    bone_anchors,
    fit_skeleton,
    image_exits,
    refine_with_votes,
)
from posedrift.skeleton._meanshift import part_modes
from posedrift.skeleton._unseen import continue_trunk, hold_limbs
from posedrift.tracking._health import Health, assess, unexplained_share
from posedrift.tracking._init import (
    CAMERA_UP,
    Calibration,
    LimbLengths,
    calibrate,
    geometric_labels,
    label_template_points,
    level_rotation,
    measure_reach,
    measure_shoulders,
    smooth_labels,
    world_up,
)
from posedrift.tracking._result import FrameResult, FrameStatus

N_PARTS = 15
_TRACK_FLOOR = 0.02  # floor of the tracked posterior in the fusion with appearance
# How much better (share of points far from their part's bone, by the labeller's labels) the
# ICP fallback's skeleton must explain the frame to replace the CPD track (``icp_fallback``).
_FALLBACK_MARGIN = 0.03
# Frames of measured hip widths whose median braces the pelvis (``brace_pelvis``): ten
# seconds at 30 fps, long enough that a crossing leg's frames do not move it.
_PELVIS_WIDTHS_KEPT = 300
# Skeletons in a row that must show the same side to the camera before the side net
# (FacingNets.side) labels: a skeleton whose left and right swap for a frame would
# otherwise be confirmed by that side's net. 3 gained on the development clips over 1, 5
# and 8 (docs/results-log.md).
_STEADY_SIDE_FRAMES = 3
# The parts whose small pieces ``merge_islands`` relabels: the upper arms, whose stray
# points in front of a hidden elbow make one. Every arm part cost the held-out clip 131_03
# 0.4-0.9 degrees over three samples, every part the climber 001_08 2.2 (docs/results-log.md).
_ISLAND_PARTS = (PART_INDEX["right_upper_arm"], PART_INDEX["left_upper_arm"])


class _RunningMedian:
    """The median of the last ``size`` values added, read in constant time.

    Kept sorted beside their order of arrival: an insertion and a removal per value,
    where ``np.median`` of the window each time read it cost several times more.
    """

    def __init__(self, size: int) -> None:
        self._order: deque[float] = deque()
        self._sorted: list[float] = []
        self._size = size

    def __len__(self) -> int:
        return len(self._sorted)

    def add(self, value: float) -> None:
        self._order.append(value)
        bisect.insort(self._sorted, value)
        if len(self._order) > self._size:
            del self._sorted[bisect.bisect_left(self._sorted, self._order.popleft())]

    def clear(self) -> None:
        self._order.clear()
        self._sorted.clear()

    @property
    def median(self) -> float:
        n, values = len(self._sorted), self._sorted
        return values[n // 2] if n % 2 else 0.5 * (values[n // 2 - 1] + values[n // 2])


_UNSEEN_CONFIDENCE = 0.3  # a joint outside the image, as fit_skeleton's joints from the prediction
# How far from the template's nearest point (metres) a joint follows the registration's
# nonrigid field, and from where on the body's rigid motion alone (_carry_joints).
_FIELD_TRUSTED, _FIELD_IGNORED = 0.03, 0.08
# Depth band (metres in front of / behind the last frame's median point depth) searched
# for the person first: limbs reach about a metre towards the camera, and walls and
# clutter outside the band never reach the floor fit and the component search.
_GATE_FRONT, _GATE_BEHIND = 1.2, 1.0
# Frames between floor searches while none has been found: a static camera that showed no
# floor shows none the next frame, and RANSAC's failed search costs 0.3 ms at 320 x 240.
_FLOOR_RETRY = 15
# A camera whose up (world_up) lies within 5 degrees of a level camera's is taken as level:
# the forest's joint votes were learnt from cameras up to about 8 degrees off level (the
# training views aim at the pelvis half the time), and on real recordings that begin
# standing the estimate of up scatters by a few degrees (UTD-MHAD: -4 to 7).
_LEVEL_COS = math.cos(math.radians(5.0))
_MIN_WORKING_FOCAL = 190.0  # pixels; see working_decimation
# Pixel offsets (rows, columns), nearest first.
_RING_ROWS, _RING_COLS = np.array(
    sorted(
        ((dr, dc) for dr in range(-3, 4) for dc in range(-3, 4) if (dr, dc) != (0, 0)),
        key=lambda o: o[0] ** 2 + o[1] ** 2,
    )
).T


@dataclass
class _State:
    """What the tracker carries from one frame to the next."""

    points: np.ndarray  # (M, 3) the labelled template (previous frame's points)
    labels: np.ndarray  # (M,)
    joints: np.ndarray  # (15, 3) previous skeleton
    registration: Any = None  # previous CPDResult (warm start)


@dataclass
class _Attempt:
    labels: np.ndarray
    fit: SkeletonFit
    health: Health
    registration: Any = None


def _rigid_fit(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The rotation and translation that best map points ``a`` onto ``b`` (Kabsch)."""
    ca, cb = a.mean(axis=0), b.mean(axis=0)
    u, _, vt = np.linalg.svd((a - ca).T @ (b - cb))
    s = np.diag([1.0, 1.0, _handedness(vt.T @ u.T)])
    rot = vt.T @ s @ u.T
    return rot, cb - rot @ ca


def _handedness(m: np.ndarray) -> float:
    """``np.sign(np.linalg.det(m))`` of an orthogonal 3 x 3 ``m`` (determinant +-1, so the
    cofactor expansion has the same sign), without LAPACK's overhead."""
    (a, b, c), (d, e, f), (g, h, i) = m.tolist()
    return float(np.sign(a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g)))


def _icp(source: np.ndarray, target: np.ndarray, iterations: int = 10):
    """Rigid ICP of ``source`` onto ``target``: (rotation, translation, nn index per target)."""
    from scipy.spatial import cKDTree

    rot, trans = np.eye(3), np.zeros(3)
    tree_t = cKDTree(target)
    moved = source
    for _ in range(iterations):
        d, idx = tree_t.query(moved)
        keep = d <= max(np.percentile(d, 90), 1e-9)
        rot, trans = _rigid_fit(source[keep], target[idx[keep]])
        moved = source @ rot.T + trans
    _, nn = cKDTree(moved).query(target)
    return rot, trans, nn


def _carry_joints(joints: np.ndarray, source: np.ndarray, moved: np.ndarray, field) -> np.ndarray:
    """The previous frame's joints moved by a nonrigid registration of its points.

    ``field`` (the registration's ``apply``) is fitted on the template points
    ``source`` (which it takes to ``moved``) and extrapolates away from them: on a
    development clip its predicted motion of the joints was 1.0 cm off their true
    motion within 3 cm of the nearest template point and 1.8 cm off beyond 15 cm
    with 24 landmarks (6.4 cm with 60), where this blend is 0.9 cm off
    (``benchmarks/carried_joints_figure.py``). Joints lie inside the body, and
    hidden or out-of-view ones far from any point: each joint follows
    the field within :data:`_FIELD_TRUSTED` of the template, the body's rigid
    motion (``source`` onto ``moved``) beyond :data:`_FIELD_IGNORED`, and a
    linear blend of the two between.
    """
    joints = np.asarray(joints, dtype=float)
    rot, trans = _rigid_fit(source, moved)
    rigid = joints @ rot.T + trans
    warped = field(joints)
    gap = np.sqrt(cdist(joints, source, "sqeuclidean").min(axis=1))
    trust = np.clip((_FIELD_IGNORED - gap) / (_FIELD_IGNORED - _FIELD_TRUSTED), 0.0, 1.0)
    blended = trust[:, None] * warped + (1.0 - trust[:, None]) * rigid
    return np.where(np.isfinite(warped), blended, rigid)


def _clip_index(index: np.ndarray, size: int) -> np.ndarray:
    """Integer ``index`` clipped to ``0 .. size - 1`` (``np.clip``'s checks of integer
    bounds cost twice the clip itself)."""
    return np.minimum(np.maximum(index, 0), size - 1)


def _facing(joints: np.ndarray, level: np.ndarray | None = None, *, signed: bool = False) -> float:
    """The facing yaw of a skeleton in degrees (NaN where it is incomplete).

    ``level``: :func:`level_rotation` of the world's up, for a camera that is not
    level (None: level); the skeleton is turned into a level camera's frame, where
    :func:`facing_yaw`'s default up holds. ``signed``: negative where the skeleton
    shows its right side.
    """
    if not np.isfinite(joints).all():
        return math.nan
    return float(facing_yaw(joints if level is None else joints @ level, signed=signed))


def _units_hint(depth: np.ndarray) -> str:
    """A hint when a frame's depth looks like millimetres given as metres, else ""."""
    valid = depth[np.isfinite(depth) & (depth > 0)]
    if valid.size == 0 or np.median(valid) <= MAX_PERSON_DEPTH:
        return ""
    return (
        f"; its median depth is {np.median(valid):g} m: raw sensor units given as metres? "
        f"Use DepthFrame.from_raw(raw, intrinsics, depth_scale=1000) for millimetres"
    )


def working_decimation(intrinsics: Intrinsics) -> int:
    """How many pixels the tracker steps over in each direction for a camera.

    The largest factor that keeps the working image at least about 320 pixels wide
    and its focal length at least 190 pixels (two thirds of the Kinect v1's at
    320 x 240, the resolution the body-part forest was trained at): 2 for 640 x 480
    cameras (Kinect v1 VGA, RealSense D435), 1 for 320 x 240 and 512 x 424.

    Examples
    --------
    >>> from posedrift.camera import camera_preset
    >>> [working_decimation(camera_preset(n)) for n in ("kinect1-qvga", "kinect1-vga", "d435")]
    [1, 2, 2]
    """
    by_focal = int(min(intrinsics.fx, intrinsics.fy) // _MIN_WORKING_FOCAL)
    by_width = round(intrinsics.width / 320)
    return max(1, min(by_focal, by_width))


class PoseTracker:
    """3-D pose from depth frames by nonrigid CPD body-part tracking.

    Implements :class:`posedrift.tracking.PoseMethod` (``name = "cpd"``): give it
    the camera's intrinsics, then depth frames one at a time; each call of
    :meth:`process` returns a frozen :class:`FrameResult`. It never sees ground truth.

    Parameters
    ----------
    intrinsics : Intrinsics
    n_points : int
        Points per frame after uniform downsampling (the paper's about 400).
    forest : BodyPartForest or "geometric", optional
        Labels the (re)initialization frames; any object with the same ``predict``
        works. Loaded lazily with ``BodyPartForest.load_default()`` when None.
        ``"geometric"`` (also the fallback where no forest can be loaded) labels an
        upright person facing the camera from body proportions alone
        (:func:`posedrift.tracking._init.geometric_labels`). Its leaves cast the
        joint votes (``vote_weights``); it labels pixels where there is no part net.
    part_net : BodyPartNet, FacingNets or "none", optional
        The per-pixel part probabilities (the appearance evidence fused every frame,
        the labels of (re)initialization frames and the judge of a failed track),
        beyond the paper: a perceptron over depth-comparison features that labels
        pixels more accurately than the forest (docs/RESULTS.md). A
        :class:`~posedrift.labelling.FacingNets` pair labels with its frontal net
        while the last skeleton faces the camera, with its turned net once that
        skeleton has turned away beyond its ``turn_gate``, with its back net (if any)
        beyond its ``back_gate``, and with its side net (if any), or that net's mirror
        image, once three skeletons in a row have shown the same side beyond its
        ``side_gate``. When None, the shipped nets
        (``FacingNets.load_default()``, loaded lazily) if ``forest`` is None
        too, else the given forest labels, as before there was a net. ``"none"``
        (also the fallback where no net can be loaded) leaves the labels to the
        forest, as in the paper. Any object with the net's ``predict_pixels`` works.
    relabel : bool
        Apply Algorithm 2 (geodesic relabelling) every frame.
    registration : {"nonrigid", "rigid"}
        The CPD transform family.
    correspondence : {"cpd", "icp"}
        ``"icp"``: nearest-neighbour correspondences after rigid ICP in the same
        loop (the ICP baseline).
    warm_start : bool
        Start each registration from the previous frame's sigma^2 (at least
        ``start_sigma`` squared) instead of the closed-form, body-sized one.
    kernel_width, smoothness, outlier_weight : float
        beta, lambda and w of nonrigid CPD (normalized units).
    max_iter : int
        EM iterations per frame at most.
    tol : float
        CPD's relative tolerance on its objective.
    start_sigma : float
        Smallest starting sigma (metres) of a warm-started registration.
    low_rank : int or None
        Rank of CPD's low-rank kernel: the number of Nyström landmarks (24 by
        default); None for the exact kernel. The angle error did not move with it
        beyond the run-to-run spread, from 16 landmarks to the exact kernel on
        synthetic clips and between 24 and 60 on real recordings, while the
        registration's cost grows with it: the registration stage took 2.1-2.6 ms a
        frame at 24 landmarks, 4.3-4.6 at 60 and 22-28 with the exact kernel, on one
        AVX2 core (docs/results-log.md, speed section).
    alpha : float
        Steepness (1/m) of Algorithm 2's sigmoid.
    height : float, optional
        The person's stature in metres, if known (otherwise measured at initialization).
    background : BackgroundModel, optional
        A static camera's background model for segmentation.
    segment_options : dict, optional
        Extra keyword arguments of :func:`posedrift.points.segment_person`.
    decimation : int, optional
        Work on every ``decimation``-th pixel of every ``decimation``-th row (the
        intrinsics scaled to match): the points are downsampled to ``n_points``
        anyway, and fewer pixels make segmentation cheaper. Default: automatic
        (:func:`working_decimation`: 2 for 640 x 480 cameras, 1 at 320 x 240); 1
        works at full resolution.
    appearance_weight : float
        Exponent ``w`` of the per-point part probabilities (the part net's, else the
        forest's) fused into the tracked label evidence every frame (a product of
        experts, beyond the paper): ``evidence(part) ~ (P_cpd + f) (P_pixel +
        appearance_floor)^w``, with ``P_cpd`` the labels carried over by
        registration and ``f`` = 0.02. It stops labels drifting over long sequences.
        0, with ``vote_weights`` ``(0, 0)``, gives the paper's pure tracking (the
        labeller then labels only the (re)initialization frames). Needs a labeller
        with ``predict_pixels``; ignored with ``forest="geometric"`` and no part net.
    appearance_floor : float
        Floor added to the per-point probabilities before fusion (how far a
        confident labeller may overrule the track).
    temporal_smoothing : float
        In [0, 1): weight of the predicted joints in each fitted joint (when
        tracking, the previous skeleton moved by the registration's warp near the
        points and by the body's rigid motion away from them, so
        motion-compensated; when re-initializing, the last pose moved with the
        body). Steadies the joints against label noise; 0 fits every frame afresh.
    vote_weights : (float, float)
        ``(trunk, arm)`` weights of the forest's joint votes (beyond the paper;
        Girshick et al. 2011): each point's leaves vote for where the joints are,
        each joint is the mode of its votes nearest the fitted skeleton's joint,
        and :func:`posedrift.skeleton.refine_with_votes` moves the head, neck and
        shoulders and turns the upper arms that far towards them in the reported
        skeleton (the track itself keeps the labels' skeleton). ``(0, 0)``, or a
        forest without votes, reports the skeleton from the labels alone.
    vote_bandwidth : float
        Mean-shift kernel width of the votes (metres).
    calibration_frames : int
        Frames, from the calibration on, over which the limb bones are measured:
        each is the median of its lengths in those frames
        (:class:`posedrift.tracking._init.LimbLengths`). 1 keeps the first frame's.
    keep_better_track : bool
        When the track fails its health check, keep it (status tracked, reported as
        doubtful) rather than take the fresh initialization where its skeleton
        explains the forest's per-point labels of the frame better (a smaller share of
        points far from their part's bone; beyond the paper). The health score
        itself favours a fresh start, whose labels are cleaned with its own skeleton.
        False: a fresh initialization replaces the failed track whenever it is
        healthy or scores lower. Needs the forest's per-point probabilities (see
        ``appearance_weight``).
    icp_fallback : float or None
        A second opinion for a doubtful CPD track (beyond the paper): where more than
        this share of the points lie far from their part's bone by the labeller's
        per-point labels, or the track fails its health check, the frame is tracked
        again from the same template with nearest-neighbour (ICP) correspondences,
        and that track is kept where it is healthy and the CPD track is not, or where
        it explains the labeller's labels better by 0.03 (``_FALLBACK_MARGIN``). On
        the development clips it ran on 18% of the frames and was kept on 0.8%
        (docs/results-log.md). None: CPD alone. Needs the per-point probabilities (see
        ``appearance_weight``); ignored with ``correspondence="icp"``.
    measure_tilt : bool
        Measure at calibration which way is up (:func:`~posedrift.tracking.world_up`:
        the floor, or the standing skeleton) and, for a camera more than 5 degrees off
        level, cast the joint votes and read the facing yaw in a level camera's frame,
        and beyond 12 degrees down ask ``part_net``'s high net (beyond the paper;
        docs/RESULTS.md, "A camera mounted high"). False takes every camera for level.
    brace_pelvis : bool
        Keep the pelvis rigid (beyond the paper): each frame's hips, which the thighs
        place, are set the median of the widths measured over the last ten seconds
        apart, their line at most 6 degrees from square to the trunk, each on its
        thigh at the thigh's length from the measured knee (``fit_skeleton``'s
        ``pelvis_width``). A leg crossing in front of a hip
        otherwise pulls that hip in and down and turns its thigh (the built-in
        motion's crossing: left hip 11 degrees off; docs/RESULTS.md, "Drift"). False
        leaves the hips where the thighs put them.
    hold_unseen : bool
        Place what leaves the image (beyond the paper): where the torso is cut by the
        image's edge and the neck unmeasured, the trunk goes on out of the image along
        the torso's axis for its calibrated length, and each unmeasured head or arm
        joint outside the image keeps the pose it had relative to the trunk in the last
        frame (:mod:`posedrift.skeleton._unseen`). A climber whose head and arms rise
        above the image: 15.31 -> 13.61 degrees over five samples (docs/RESULTS.md).
        False fills them in from the prediction, as ``fit_skeleton`` does.
    merge_islands : bool
        Relabel stray upper-arm points before each tracked frame's skeleton fit
        (beyond the paper; :func:`~posedrift.labelling.merge_islands`): a piece of at
        most 8 points labelled upper arm, cut off in the graph from the arm's main
        piece, takes its neighbours' label. With a forearm pointed at the camera its
        elbow is hidden, and a few of its points labelled upper arm otherwise make an
        elbow 10-15 cm in front of the true one (the built-in motion's drift: 1.29x ->
        1.10x over five samples; docs/RESULTS.md, "Drift"). False fits the labels as
        they are.
    blas_threads : int or None
        Threads the BLAS library may use while a frame is processed (the part net's
        matrix products). The matrices are small: on two cores, two threads made one
        tracker alone 5-13% faster but two trackers side by side 2.5 times slower
        (docs/RESULTS.md, speed section), so one thread by default keeps the speed
        whatever else runs. None leaves the library's own setting.
    rng : int or Generator
        Seeds downsampling and RANSAC (runs are repeatable for an int).

    Examples
    --------
    >>> import numpy as np
    >>> from posedrift.camera import DepthFrame, camera_preset
    >>> k = camera_preset("kinect1-qvga")
    >>> tracker = PoseTracker(k)
    >>> result = tracker.process(DepthFrame(np.zeros(k.shape, np.float32), k, index=0))
    >>> result.status.value
    'no_person'
    """

    name = "cpd"

    def __init__(
        self,
        intrinsics: Intrinsics,
        *,
        n_points: int = 400,
        forest: Any = None,
        part_net: Any = None,
        relabel: bool = True,
        registration: str = "nonrigid",
        correspondence: str = "cpd",
        warm_start: bool = True,
        kernel_width: float = 0.5,
        smoothness: float = 1.0,
        outlier_weight: float = 0.05,
        max_iter: int = 20,
        tol: float = 1e-4,
        start_sigma: float = 0.02,
        low_rank: int | None = 24,
        alpha: float = 60.0,
        relabel_mode: str = "gate",
        evidence_floor: float = 0.05,
        height: float | None = None,
        background: BackgroundModel | None = None,
        segment_options: dict | None = None,
        decimation: int | None = None,
        min_points: int = 60,
        appearance_weight: float = 3.0,
        appearance_floor: float = 0.01,
        temporal_smoothing: float = 0.3,
        vote_weights: tuple[float, float] = (0.5, 0.4),
        vote_bandwidth: float = 0.05,
        calibration_frames: int = 30,
        keep_better_track: bool = True,
        icp_fallback: float | None = 0.08,
        measure_tilt: bool = True,
        brace_pelvis: bool = True,
        hold_unseen: bool = True,
        merge_islands: bool = True,
        blas_threads: int | None = 1,
        rng: int | np.random.Generator | None = 0,
    ) -> None:
        caller = "PoseTracker"
        if not isinstance(intrinsics, Intrinsics):
            raise ValueError(
                f"The 'intrinsics' argument of {caller} must be an Intrinsics. "
                f"Got {type(intrinsics).__name__} instead."
            )
        if registration not in ("nonrigid", "rigid"):
            raise ValueError(
                f"The 'registration' parameter of {caller} must be 'nonrigid' or 'rigid'. "
                f"Got {registration!r} instead."
            )
        if correspondence not in ("cpd", "icp"):
            raise ValueError(
                f"The 'correspondence' parameter of {caller} must be 'cpd' or 'icp'. "
                f"Got {correspondence!r} instead."
            )
        self.n_points = check_scalar(
            n_points, "n_points", low=20, include_low=True, integer=True, caller=caller
        )
        self.kernel_width = check_scalar(kernel_width, "kernel_width", low=0.0, caller=caller)
        self.smoothness = check_scalar(smoothness, "smoothness", low=0.0, caller=caller)
        self.outlier_weight = check_scalar(
            outlier_weight, "outlier_weight", low=0.0, high=1.0, include_low=True, caller=caller
        )
        self.max_iter = check_scalar(
            max_iter, "max_iter", low=1, include_low=True, integer=True, caller=caller
        )
        self.tol = check_scalar(tol, "tol", low=0.0, caller=caller)
        self.start_sigma = check_scalar(start_sigma, "start_sigma", low=0.0, caller=caller)
        if low_rank is not None:
            low_rank = check_scalar(
                low_rank, "low_rank", low=1, include_low=True, integer=True, caller=caller
            )
        self.low_rank = low_rank
        self.alpha = check_scalar(alpha, "alpha", low=0.0, caller=caller)
        if relabel_mode not in ("gate", "paper"):
            raise ValueError(
                f"The 'relabel_mode' parameter of {caller} must be 'gate' or 'paper'. "
                f"Got {relabel_mode!r} instead."
            )
        self.relabel_mode = relabel_mode
        self.evidence_floor = check_scalar(
            evidence_floor, "evidence_floor", low=0.0, include_low=True, caller=caller
        )
        if height is not None:
            height = check_scalar(height, "height", low=0.5, high=2.6, caller=caller)
        self.height = height
        self.min_points = int(min_points)
        self.appearance_weight = check_scalar(
            appearance_weight, "appearance_weight", low=0.0, include_low=True, caller=caller
        )
        self.appearance_floor = check_scalar(
            appearance_floor, "appearance_floor", low=0.0, include_low=True, caller=caller
        )
        self.temporal_smoothing = check_scalar(
            temporal_smoothing,
            "temporal_smoothing",
            low=0.0,
            high=1.0,
            include_low=True,
            caller=caller,
        )
        if np.shape(vote_weights) != (2,):
            raise ValueError(
                f"The 'vote_weights' parameter of {caller} must be two weights (trunk, "
                f"arm). Got {vote_weights!r} instead."
            )
        self.vote_weights = tuple(
            check_scalar(
                w, name, low=0.0, high=1.0, include_low=True, include_high=True, caller=caller
            )
            for w, name in zip(vote_weights, ("vote_weights[0]", "vote_weights[1]"), strict=True)
        )
        self.vote_bandwidth = check_scalar(vote_bandwidth, "vote_bandwidth", low=0.0, caller=caller)
        self.calibration_frames = check_scalar(
            calibration_frames,
            "calibration_frames",
            low=1,
            include_low=True,
            integer=True,
            caller=caller,
        )
        self.keep_better_track = bool(keep_better_track)
        self.measure_tilt = bool(measure_tilt)
        self.brace_pelvis = bool(brace_pelvis)
        self.hold_unseen = bool(hold_unseen)
        self.merge_islands = bool(merge_islands)
        if blas_threads is not None:
            blas_threads = check_scalar(
                blas_threads, "blas_threads", low=1, include_low=True, integer=True, caller=caller
            )
        self.blas_threads = blas_threads
        if icp_fallback is not None:
            icp_fallback = check_scalar(
                icp_fallback,
                "icp_fallback",
                low=0.0,
                high=1.0,
                include_low=True,
                include_high=True,
                caller=caller,
            )
        self.icp_fallback = icp_fallback
        self._frame_votes: tuple[np.ndarray, ...] | None = None
        self.relabel = bool(relabel)
        self.registration = registration
        self.correspondence = correspondence
        self.warm_start = bool(warm_start)
        self.forest = forest
        if isinstance(part_net, str) and part_net != "none":
            raise ValueError(
                f"The 'part_net' parameter of {caller} must be a BodyPartNet, a FacingNets, "
                f"'none' or None. Got {part_net!r} instead."
            )
        if part_net is None and forest is not None:
            part_net = "none"  # a forest of one's own labels, as before there was a net
        self.part_net = part_net
        self.background = background
        self.segment_options = dict(segment_options or {})
        if decimation is not None:
            decimation = check_scalar(
                decimation, "decimation", low=1, include_low=True, integer=True, caller=caller
            )
        self.decimation = decimation
        self._working_backgrounds: dict[int, BackgroundModel] = {}
        self._seed = rng
        self._raise_errors = False  # development switch: let exceptions escape process()
        self.reset(intrinsics)

    # ------------------------------------------------------------------ public API
    def reset(self, intrinsics: Intrinsics) -> None:
        """Forget the track (and the calibration) and prepare for a new sequence."""
        if not isinstance(intrinsics, Intrinsics):
            raise ValueError(
                f"The 'intrinsics' argument of PoseTracker.reset must be an Intrinsics. "
                f"Got {type(intrinsics).__name__} instead."
            )
        self.intrinsics = intrinsics
        seed = int(check_rng(self._seed).integers(2**31))
        self._downsample_rng = np.random.default_rng(seed)
        self._downsample_start = self._downsample_rng.bit_generator.state
        self._last_joints: np.ndarray | None = None
        self._last_centre: np.ndarray | None = None
        # The signed facing yaw of the last skeletons (see _shown_side).
        self._facings: deque[float] = deque(maxlen=_STEADY_SIDE_FRAMES)
        self._state: _State | None = None
        self._last_in_view: tuple[Any, Any] = (None, None)  # (state's joints, their _in_view)
        self._calibration: Calibration | None = None
        self._limb_lengths: LimbLengths | None = None
        self._measured_calibration: Calibration | None = None
        self._pelvis_widths = _RunningMedian(_PELVIS_WIDTHS_KEPT)
        self._voxel: float | None = None
        self._person_depth: float | None = None
        self._floor: tuple[np.ndarray, float] | None = None
        self._floorless_frames = 0  # frames segmented while no floor plane is known
        self._level_cache: tuple[np.ndarray, np.ndarray] | None = None
        self._seed_registration = None

    def load_models(self) -> PoseTracker:
        """Load the forest and the part nets now instead of on the first frame.

        They are otherwise loaded lazily, which makes the first call of
        :meth:`process` take a few hundred milliseconds; load them first where
        frames are timed or come from a live camera. Models given to the
        constructor are kept; loading twice does nothing more.

        Returns
        -------
        PoseTracker
            This tracker.
        """
        self._get_forest()
        self._get_labeller()
        return self

    @property
    def calibration(self) -> Calibration | None:
        """The person's calibration (stature, bone lengths), once initialized."""
        return self._calibration

    def process(self, frame: DepthFrame) -> FrameResult:
        """Recover the pose in one frame.

        Bad content (no person, all zeros, NaNs, unusable labels) gives a result
        with status ``no_person`` or ``lost`` and a message naming the frame; the
        next frame is then tracked or re-initialized. Only a non-``DepthFrame``
        argument raises.

        Parameters
        ----------
        frame : DepthFrame

        Returns
        -------
        FrameResult
        """
        if not isinstance(frame, DepthFrame):
            raise ValueError(
                f"The 'frame' argument of PoseTracker.process must be a DepthFrame. "
                f"Got {type(frame).__name__} instead."
            )
        where = f"frame {frame.index}" + (f" ({frame.source})" if frame.source else "")
        try:
            with blas_limited(self.blas_threads):
                return self._process(frame, where)
        except Exception as exc:
            if self._raise_errors:
                raise
            self._state = self._person_depth = None
            return FrameResult.empty(
                frame.index,
                FrameStatus.LOST,
                f"{where}: could not be processed ({type(exc).__name__}: {exc})",
                timestamp=frame.timestamp,
            )

    # ------------------------------------------------------------------ the loop
    def _process(self, frame: DepthFrame, where: str) -> FrameResult:
        timings: dict[str, float] = {}
        t0 = time.perf_counter()
        frame = self._working_frame(frame)
        intr = frame.intrinsics
        depth = frame.depth
        if not depth.max() > 0:  # (a DepthFrame's depth is finite and never negative)
            self._state = self._person_depth = None
            return FrameResult.empty(
                frame.index,
                FrameStatus.NO_PERSON,
                f"{where}: no valid depth in the frame",
                timestamp=frame.timestamp,
            )
        mask = self._segment(frame)
        n_mask = int(np.count_nonzero(mask))
        t1 = time.perf_counter()
        timings["segment"] = 1e3 * (t1 - t0)
        if n_mask < self.min_points:
            self._state = self._person_depth = None
            return FrameResult.empty(
                frame.index,
                FrameStatus.NO_PERSON,
                f"{where}: no person found ({n_mask} foreground pixels)" + _units_hint(depth),
                timestamp=frame.timestamp,
                timings_ms=timings,
            )
        full, pixels = backproject(depth, intr, mask)
        # The same seed every frame: identical frames give identical points. (The
        # generator is rewound to its seeded state: seeding a new one costs more.)
        self._downsample_rng.bit_generator.state = self._downsample_start
        # Back-projected valid depth: finite points, as downsample would check.
        points, self._voxel = downsample_checked(
            full, self.n_points, self._voxel, self._downsample_rng, return_voxel_size=True
        )
        self._person_depth = median(points[:, 2])
        t2 = time.perf_counter()
        timings["points"] = 1e3 * (t2 - t1)
        graph = geodesic_graph(points)
        timings["graph"] = 1e3 * (time.perf_counter() - t2)

        status = FrameStatus.TRACKED
        attempt = None
        message = ""
        tracking = self._state is not None and self._calibration is not None
        t_app = time.perf_counter()
        appearance, self._frame_votes = self._pixel_evidence(
            depth, intr, mask, points, appearance=tracking
        )
        timings["appearance"] = 1e3 * (time.perf_counter() - t_app)
        if tracking:
            attempt = self._track(points, graph, timings, appearance)
            if not attempt.health.ok:
                message = f"{where}: track lost ({attempt.health.reason}); re-initialized"
        if attempt is None or not attempt.health.ok:
            t3 = time.perf_counter()
            fresh = self._initialize(depth, intr, mask, full, pixels, points, graph)
            timings["initialize"] = 1e3 * (time.perf_counter() - t3)
            if fresh is not None and self._replaces_track(fresh, attempt, points, appearance):
                attempt = fresh
                status = FrameStatus.REINITIALIZED
            usable = attempt is not None and np.isfinite(attempt.fit.joints).all()
            if not usable:
                reason = "no usable body-part labels" if attempt is None else attempt.health.reason
                # Whatever was segmented is no person we can fit: search every depth next.
                self._state = self._person_depth = None
                timings["total"] = 1e3 * (time.perf_counter() - t0)
                return FrameResult.empty(
                    frame.index,
                    FrameStatus.LOST,
                    f"{where}: no pose ({reason})",
                    timestamp=frame.timestamp,
                    timings_ms=timings,
                )
            if not attempt.health.ok:
                # Neither the track nor a re-initialization is convincing: keep the
                # better one, with less confidence.
                message = f"{where}: doubtful pose ({attempt.health.reason})"
                attempt.fit = replace(attempt.fit, confidence=0.5 * attempt.fit.confidence)
        fit = attempt.fit
        self._last_joints, self._last_centre = fit.joints, points.mean(axis=0)
        self._facings.append(_facing(fit.joints, self._level(), signed=True))
        self._state = _State(
            points=points,
            labels=attempt.labels,
            joints=fit.joints,
            registration=attempt.registration,
        )
        self._measure_limbs(points, attempt.labels, graph)
        if math.isfinite(fit.pelvis_width):
            self._pelvis_widths.add(fit.pelvis_width)
        # The votes refine what is reported, not the track: fed back as the next
        # frame's prediction, a refined arm could lock in a wrong pose (docs/results-log.md).
        t_votes = time.perf_counter()
        reported = self._refine_with_votes(fit.joints)
        timings["skeleton"] = timings.get("skeleton", 0.0) + 1e3 * (time.perf_counter() - t_votes)
        timings["total"] = 1e3 * (time.perf_counter() - t0)
        return FrameResult(
            index=frame.index,
            status=status,
            joints=reported,
            confidence=fit.confidence,
            points=points,
            labels=attempt.labels,
            timestamp=frame.timestamp,
            timings_ms=timings,
            message=message,
        )

    def _replaces_track(self, fresh: _Attempt, track: _Attempt | None, points, appearance) -> bool:
        """Whether a fresh initialization replaces the track that failed its health check."""
        if track is None:
            return True
        if (
            self.keep_better_track
            and appearance is not None
            and np.isfinite(track.fit.joints).all()
            and np.isfinite(fresh.fit.joints).all()
        ):
            # Judged by the forest's labels, which neither skeleton was fitted to.
            forest_labels = np.argmax(appearance, axis=1)
            height = self._calibration.height
            kept = unexplained_share(points, forest_labels, track.fit.joints, height=height)
            if kept < unexplained_share(points, forest_labels, fresh.fit.joints, height=height):
                return False
        return fresh.health.ok or fresh.health.score < track.health.score

    def _measure_limbs(self, points, labels, graph) -> None:
        """Measure the limb bones in this frame while the calibration is recent."""
        if self._calibration is None:  # this frame's pose was not good enough to calibrate
            return
        if self._calibration is not self._measured_calibration:
            # Calibrated afresh (the only other source of a new Calibration): start over.
            self._limb_lengths = LimbLengths(self.calibration_frames)
            self._pelvis_widths.clear()
        if not self._limb_lengths.done:
            height = self._calibration.height
            self._limb_lengths.add(points, labels, (graph.rows, graph.cols), height)
            self._calibration = self._limb_lengths.refine(self._calibration)
        self._measured_calibration = self._calibration

    def _working_frame(self, frame: DepthFrame) -> DepthFrame:
        """The frame subsampled by the decimation factor (as it is where that is 1)."""
        step = self.decimation or working_decimation(frame.intrinsics)
        if step == 1:
            return frame
        k = frame.intrinsics
        # Pixel (step i, step j) becomes (i, j): u_old = step * u_new, so the focal
        # lengths and the principal point divide by step.
        depth = np.ascontiguousarray(frame.depth[::step, ::step])
        working = Intrinsics(
            fx=k.fx / step,
            fy=k.fy / step,
            cx=k.cx / step,
            cy=k.cy / step,
            width=depth.shape[1],
            height=depth.shape[0],
        )
        return replace(frame, depth=depth, intrinsics=working)

    def _working_background(self, shape: tuple[int, int]) -> BackgroundModel | None:
        """The background model at the working resolution (subsampled once, then kept)."""
        bg = self.background
        if bg is None or bg.depth_ is None or bg.depth_.shape == shape:
            return bg
        step = -(-bg.depth_.shape[0] // shape[0])
        if step not in self._working_backgrounds:
            sub = copy.copy(bg)
            sub.depth_ = np.ascontiguousarray(bg.depth_[::step, ::step])
            self._working_backgrounds[step] = sub
        return self._working_backgrounds[step]

    def _segment(self, frame: DepthFrame) -> np.ndarray:
        """The person's pixels (:meth:`_find_person`), keeping the floor plane found.

        The last floor plane found is tried first (a static camera's floor stays
        put). While none has been found, the floor is searched for only every
        :data:`_FLOOR_RETRY` frames, and at once where the person is not found
        without it (a floor that came into view joins the person to a component too
        large to be one).
        """
        searching = self._floor is not None or self._floorless_frames % _FLOOR_RETRY == 0
        mask, floor = self._find_person(frame, search_floor=searching)
        if not searching and np.count_nonzero(mask) < self.min_points:
            mask, floor = self._find_person(frame, search_floor=True)
        self._floor = floor if floor is not None else self._floor
        self._floorless_frames = 0 if self._floor is not None else self._floorless_frames + 1
        return mask

    def _find_person(self, frame: DepthFrame, *, search_floor: bool):
        """``(mask, floor)`` of :func:`segment_person`: first within a depth band
        around the last frame's person.

        The band drops walls and far clutter before the floor fit and the component
        search (a noisy room at 320 x 240: 4.3 -> 1.6 ms); where it holds no person
        (one who jumped towards the camera, or left), the whole depth range is
        searched.
        """
        options = {
            "background": self._working_background(frame.depth.shape),
            "rng": 0,
            **self.segment_options,
            "floor": self._floor,
            "return_floor": True,
        }
        if not search_floor:
            options["remove_floor"] = False
        if self._person_depth is not None:
            defaults = segment_person.__kwdefaults__
            near = options.get("min_depth", defaults["min_depth"])
            far = options.get("max_depth", defaults["max_depth"])
            band = {
                "min_depth": max(near, self._person_depth - _GATE_FRONT),
                "max_depth": min(far, self._person_depth + _GATE_BEHIND),
            }
            mask, floor = segment_person(frame, **{**options, **band})
            if np.count_nonzero(mask) >= self.min_points:
                return mask, floor
        return segment_person(frame, **options)

    def _register(
        self, source: np.ndarray, target: np.ndarray, labels: np.ndarray, correspondence: str
    ):
        """Registration of the template onto the frame: (posterior (N,15), warp, result, sigma)."""
        if correspondence == "icp":
            rot, trans, nn = _icp(source, target)
            post = np.zeros((len(target), N_PARTS))
            post[np.arange(len(target)), labels[nn]] = 1.0
            moved = source @ rot.T + trans
            sigma = float(np.sqrt(np.mean(np.sum((target - moved[nn]) ** 2, axis=1))))
            return post, (lambda p: np.asarray(p) @ rot.T + trans), None, sigma
        from posedrift.registration import ConvergenceWarning, register_nonrigid, register_rigid

        prev = None
        if self.warm_start and self.registration == "nonrigid":
            # Start the EM at a small sigma^2 (the previous frame's, at least start_sigma):
            # from a cold, body-sized sigma^2 the GMM first shrinks and then slides along
            # the surface, which moves labels across part boundaries.
            prev = self._state.registration if self._state is not None else None
            if prev is None or prev.kind != "nonrigid":
                prev = self._seed_result(source)
            sigma2 = max(float(prev.sigma2), self.start_sigma**2)
            if sigma2 != prev.sigma2:  # (only sigma^2 is read from it: no copy where it stays)
                prev = replace(prev, sigma2=sigma2)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ConvergenceWarning)
            if self.registration == "rigid":
                res = register_rigid(
                    source,
                    target,
                    outlier_weight=self.outlier_weight,
                    tol=self.tol,
                    max_iter=self.max_iter,
                    warm_start=None,
                )
            else:
                res = register_nonrigid(
                    source,
                    target,
                    kernel_width=self.kernel_width,
                    smoothness=self.smoothness,
                    outlier_weight=self.outlier_weight,
                    tol=self.tol,
                    max_iter=self.max_iter,
                    warm_start=prev,
                    low_rank=self.low_rank,
                    accelerate=True,
                    # The E-step's kernel values in float32 (its sums in float64): 0.4 ms a
                    # frame faster. On six clips of 300 frames one point's label changed in
                    # three frames; elsewhere the joints moved by at most 23 micrometres.
                    dtype=np.float32,
                )
        post = res.transfer_labels(labels.astype(np.int64), N_PARTS)
        warp = res.apply
        if self.registration == "nonrigid":
            warp = lambda joints: _carry_joints(joints, source, res.moved, res.apply)  # noqa: E731
        return post, warp, res, float(np.sqrt(max(res.sigma2, 0.0)))

    def _seed_result(self, source: np.ndarray):
        """A nonrigid result to carry the starting sigma^2 (the API's warm start)."""
        from posedrift.registration import ConvergenceWarning, register_nonrigid

        if self._seed_registration is None:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", ConvergenceWarning)
                self._seed_registration = register_nonrigid(source[:20], source[:20], max_iter=1)
        return self._seed_registration

    def _pixel_evidence(self, depth, intr, mask, points, *, appearance: bool):
        """What the labeller and the forest say at each point's pixel.

        Returns ``(probabilities, votes)``: ``probabilities`` is ``(N, 15)`` from the
        labeller (:meth:`_get_labeller`; None unless ``appearance`` and an appearance
        weight); ``votes`` the forest's joint votes cast (:meth:`JointVotes.cast`;
        None where the forest has none or the vote weights are 0). Where the forest
        is the labeller, one descent serves both.
        """
        forest = self._get_forest()
        labeller = self._get_labeller()
        want_parts = appearance and self.appearance_weight > 0
        want_parts = want_parts and hasattr(labeller, "predict_pixels")
        want_votes = max(self.vote_weights) > 0 and getattr(forest, "votes", None) is not None
        want_votes = want_votes and hasattr(forest, "predict_pixels")
        if not (want_parts or want_votes):
            return None, None
        # A point is a voxel centroid: take the pixel it projects to where that pixel
        # is the person's, else the nearest of the person's pixels within 3 pixels
        # (none: a uniform row, no appearance evidence).
        height, width = depth.shape
        uv = np.rint(project(points, intr)).astype(np.intp)
        rows = _clip_index(uv[:, 1], height)
        cols = _clip_index(uv[:, 0], width)
        off = np.flatnonzero(~mask[rows, cols])
        if len(off):  # every ring offset of every such point at once; the first hit wins
            r = _clip_index(rows[off, None] + _RING_ROWS, height)
            c = _clip_index(cols[off, None] + _RING_COLS, width)
            hit = mask[r, c]
            found = np.flatnonzero(hit.any(axis=1))
            first = hit[found].argmax(axis=1)
            rows[off[found]], cols[off[found]] = r[found, first], c[found, first]
        pixels = np.column_stack([rows, cols])
        # Checked and probed once for both models where they are posedrift's own.
        checked = CheckedPixels(depth, mask, pixels, intr, "PoseTracker")

        def predict(model, **options):
            if hasattr(model, "_predict_checked"):
                return model._predict_checked(checked, **options)
            return model.predict_pixels(depth, pixels, intr, mask=mask, **options)

        parts = votes = None
        if want_votes:
            forest_parts, leaves = predict(forest, return_leaves=True)
            # Each point votes from where it lies, not from the pixel it was read at. The
            # votes' offsets were learnt from level cameras: cast in a level frame.
            level = self._level()
            if level is None:
                votes = forest.votes.cast(points, leaves, joints=VOTED_JOINTS)
            else:
                where, *rest = forest.votes.cast(points @ level, leaves, joints=VOTED_JOINTS)
                votes = (where @ level.T, *rest)
        if want_parts:
            reuse = want_votes and labeller is forest
            parts = forest_parts if reuse else predict(labeller)
        return parts, votes

    def _fuse(self, post: np.ndarray, appearance: np.ndarray | None) -> np.ndarray:
        """Product of experts of the tracked posterior and the per-pixel probabilities."""
        if appearance is None:
            return post
        fused = row_shares(post, post.sum(axis=1, keepdims=True), 1e-12)
        fused += _TRACK_FLOOR
        fused *= (appearance + self.appearance_floor) ** self.appearance_weight
        fused /= fused.sum(axis=1, keepdims=True)
        return fused

    def _track(
        self, points: np.ndarray, graph, timings: dict[str, float], appearance=None
    ) -> _Attempt:
        """This frame tracked from the last one, with ICP's second opinion (``icp_fallback``)."""
        attempt = self._track_with(self.correspondence, points, graph, timings, appearance)
        if self.correspondence != "cpd" or self.icp_fallback is None or appearance is None:
            return attempt
        # Judged by the labeller's labels, which neither registration produced.
        labeller_labels = np.argmax(appearance, axis=1)
        height = self._calibration.height

        def unexplained(a: _Attempt) -> float:
            if not np.isfinite(a.fit.joints).all():
                return math.inf
            return unexplained_share(points, labeller_labels, a.fit.joints, height=height)

        share = unexplained(attempt)
        if attempt.health.ok and share <= self.icp_fallback:
            return attempt
        t0 = time.perf_counter()
        other = self._track_with("icp", points, graph, {}, appearance)
        timings["fallback"] = 1e3 * (time.perf_counter() - t0)
        if attempt.health.ok != other.health.ok:
            return other if other.health.ok else attempt
        return other if unexplained(other) < share - _FALLBACK_MARGIN else attempt

    def _track_with(
        self, correspondence: str, points: np.ndarray, graph, timings, appearance
    ) -> _Attempt:
        """One frame tracked from the template with ``correspondence`` ("cpd" or "icp")."""
        state, cal = self._state, self._calibration
        t0 = time.perf_counter()
        post, warp, res, sigma = self._register(state.points, points, state.labels, correspondence)
        t1 = time.perf_counter()
        timings["register"] = 1e3 * (t1 - t0)
        post = self._fuse(post, appearance)
        labels = np.argmax(post, axis=1)
        empty = post.sum(axis=1) <= 1e-12
        if empty.any():  # Outliers: the label of the nearest inlier.
            inl = ~empty
            if inl.any():
                from scipy.spatial import cKDTree

                _, nn = cKDTree(points[inl]).query(points[empty])
                labels[empty] = labels[inl][nn]
        prediction = warp(state.joints)
        if self.relabel:
            anchors = bone_anchors(prediction, cal.bone_lengths)
            labels = relabel(
                points,
                labels,
                anchors,
                height=cal.height,
                ratios=cal.reach,
                alpha=self.alpha,
                evidence=post,
                graph=graph,
                keep_plausible=self.relabel_mode == "gate",
                evidence_floor=self.evidence_floor,
            )
        t2 = time.perf_counter()
        timings["relabel"] = 1e3 * (t2 - t1)
        attempt = self._fit(points, labels, graph, prediction, sigma=sigma)
        attempt.registration = res
        timings["skeleton"] = 1e3 * (time.perf_counter() - t2)
        return attempt

    def _fit_with(self, cal, points, labels, graph) -> _Attempt:
        saved, self._calibration = self._calibration, cal
        try:
            return self._fit(points, labels, graph, None)
        finally:
            self._calibration = saved

    def _fit(
        self, points, labels, graph, prediction, *, sigma=None, anchor_shoulders=True
    ) -> _Attempt:
        cal = self._calibration
        if self.merge_islands and prediction is not None:
            # While tracking only: a sparse first frame's upper arm may lie in pieces.
            labels = merge_islands(labels, graph, _ISLAND_PARTS)
        # Without anchoring, the shoulders are where the arms put them (calibration),
        # from the elbows where their boundaries lie, as the limb lengths were measured.
        unanchored = {} if anchor_shoulders else {"shoulder_anchor": 0.0, "elbow_shift": 0.0}
        modes = part_modes(points, labels, bandwidth=0.06)
        exits = self._image_exits(points, labels)
        fit = fit_skeleton(
            points,
            labels,
            bone_lengths=cal.bone_lengths,
            edges=(graph.rows, graph.cols),
            modes=modes,
            prediction=prediction,
            height=cal.height,
            smoothing=self.temporal_smoothing,
            shoulder_offset=cal.shoulders,
            exits=exits,
            facing=None if prediction is None else _facing(prediction, self._level()),
            pelvis_width=self._pelvis_width() if anchor_shoulders else None,
            **unanchored,
        )
        in_view = self._in_view(fit.joints)
        if prediction is not None and self.hold_unseen:
            placed = self._place_unseen(fit, points, labels, exits, in_view)
            if placed is not fit:
                fit, in_view = placed, self._in_view(placed.joints)
        health = assess(
            points,
            labels,
            fit.joints,
            fit.measured,
            height=cal.height,
            sigma=sigma,
            in_view=in_view,
        )
        # A joint outside the image is inferred, never seen: at most the confidence of
        # one filled in from the prediction.
        outside = ~in_view & np.isfinite(fit.joints).all(axis=1)
        if outside.any():
            capped = np.where(
                outside, np.minimum(fit.confidence, _UNSEEN_CONFIDENCE), fit.confidence
            )
            fit = replace(fit, confidence=capped)
        return _Attempt(labels=labels, fit=fit, health=health)

    def _place_unseen(self, fit: SkeletonFit, points, labels, exits, in_view) -> SkeletonFit:
        """``fit`` with the trunk continued out of the image and unseen limbs held on it
        (``hold_unseen``; :mod:`posedrift.skeleton._unseen`); ``in_view``: its joints'."""
        last = None if self._state is None else self._state.joints
        if last is None or not (np.isfinite(last).all() and np.isfinite(fit.joints).all()):
            return fit
        if self._last_in_view[0] is not last:  # once a frame, not once a fit
            self._last_in_view = (last, self._in_view(last))
        joints = continue_trunk(
            fit.joints,
            fit.measured,
            points,
            labels,
            previous=last,
            exits=exits,
            bone_lengths=self._calibration.bone_lengths,
        )
        joints = hold_limbs(
            joints,
            fit.measured,
            last,
            in_view=in_view if joints is fit.joints else self._in_view(joints),
            previous_in_view=self._last_in_view[1],
        )
        return fit if joints is fit.joints else replace(fit, joints=joints)

    def _pelvis_width(self) -> float | None:
        """The hips' width to brace the pelvis to: the median of the widths measured so far."""
        if not self.brace_pelvis or not self._pelvis_widths:
            return None
        return self._pelvis_widths.median

    def _refine_with_votes(self, joints: np.ndarray) -> np.ndarray:
        """``joints`` moved towards this frame's joint votes (as they are without votes)."""
        if self._frame_votes is None or not np.isfinite(joints).all():
            return joints
        from posedrift.labelling import joint_modes

        voted = joint_modes(
            *self._frame_votes, joints, bandwidth=self.vote_bandwidth, joints=VOTED_JOINTS
        )
        trunk, arm = self.vote_weights
        return refine_with_votes(joints, voted, trunk_weight=trunk, arm_weight=arm)

    def _image_exits(self, points: np.ndarray, labels: np.ndarray) -> np.ndarray:
        """``(15, 3)`` where each part leaves the image (NaN inside it): :func:`image_exits`."""
        step = self.decimation or working_decimation(self.intrinsics)
        # One working pixel (``step`` of the camera's) and a voxel from the border.
        return image_exits(
            points, labels, self.intrinsics, margin=step, voxel_size=self._voxel or 0.0
        )

    def _in_view(self, joints: np.ndarray) -> np.ndarray:
        """``(15,)`` whether each joint projects inside the image (False where unknown)."""
        k = self.intrinsics
        out = np.zeros(len(joints), dtype=bool)
        known = np.isfinite(joints).all(axis=1) & (joints[:, 2] > 0)
        if known.any():
            u, v = project(joints[known], k).T
            out[known] = (u >= 0) & (u <= k.width - 1) & (v >= 0) & (v <= k.height - 1)
        return out

    # ------------------------------------------------------------------ initialization
    def _level(self) -> np.ndarray | None:
        """:func:`level_rotation` of the calibration's up; None before calibration or
        for a camera within 5 degrees of level (``_LEVEL_COS``)."""
        cal = self._calibration
        if not self.measure_tilt or cal is None or cal.up @ CAMERA_UP > _LEVEL_COS:
            return None
        if self._level_cache is None or self._level_cache[0] is not cal.up:
            self._level_cache = (cal.up, level_rotation(cal.up))
        return self._level_cache[1]

    def _camera_tilt(self) -> float | None:
        """Degrees the camera looks down, from the calibration's up (None before it, or
        without ``measure_tilt``)."""
        if not self.measure_tilt or self._calibration is None:
            return None
        up = self._calibration.up
        return math.degrees(math.atan2(-float(up[2]), -float(up[1])))

    def _get_forest(self):
        """The forest, loaded on first use; "geometric" where none can be loaded."""
        if self.forest is None:
            try:
                from posedrift.labelling import BodyPartForest

                self.forest = BodyPartForest.load_default()
            except (OSError, ValueError, ImportError, AttributeError):
                self.forest = "geometric"
        return self.forest

    def _get_labeller(self, *, fresh: bool = False):
        """What labels pixels this frame: the part net (loaded on first use; of a
        :class:`FacingNets` pair, the one for the last skeleton's facing) or else the forest.

        ``fresh``: for a frame labelled afresh (an initialization), which asks no side
        net: its labels decide the new skeleton's left and right, and a side taken
        from a lost track would decide them instead.
        """
        if self.part_net is None:
            try:
                from posedrift.labelling import FacingNets

                self.part_net = FacingNets.load_default()
            except (OSError, ValueError, ImportError, AttributeError):
                self.part_net = "none"
        if isinstance(self.part_net, str):
            return self._get_forest()
        if hasattr(self.part_net, "select"):
            last = self._last_joints
            facing = None if last is None else _facing(last, self._level())
            side = None if fresh else self._shown_side()
            if side is None:  # FacingNets-like objects without sides keep working
                return self.part_net.select(facing, tilt=self._camera_tilt())
            return self.part_net.select(facing, tilt=self._camera_tilt(), side=side)
        return self.part_net

    def _shown_side(self) -> str | None:
        """``"left"`` or ``"right"`` where the last ``_STEADY_SIDE_FRAMES`` skeletons all
        showed that side to the camera, turned beyond the part nets' ``turn_gate`` and
        ``side_gate`` and short of their ``back_gate``; else None."""
        facings = self._facings
        if len(facings) < _STEADY_SIDE_FRAMES or getattr(self.part_net, "side", None) is None:
            return None
        nets = self.part_net
        low, high = max(nets.turn_gate, nets.side_gate), nets.back_gate
        if all(low < yaw <= high for yaw in facings):
            return "left"
        if all(-high <= yaw < -low for yaw in facings):
            return "right"
        return None

    def _initialize(self, depth, intr, mask, full, pixels, points, graph) -> _Attempt | None:
        """Label the frame afresh, calibrate (first time) and fit a skeleton.

        The labeller (:meth:`_get_labeller`) labels the frame; where its skeleton is
        not healthy, the geometric labelling of an upright person is tried too and
        the better one is kept (a labelling built from its own skeleton always looks
        consistent, so it is only a fallback).
        """
        labeller = self._get_labeller(fresh=True)
        sources = [labeller]
        if not (isinstance(labeller, str) and labeller == "geometric"):
            sources.append("geometric")
        saved = self._calibration
        best = None
        for source in sources:
            self._calibration = saved
            attempt = self._initialize_from(source, depth, intr, mask, full, pixels, points, graph)
            if attempt is not None and (
                best is None or attempt.health.score < best[0].health.score
            ):
                best = (attempt, self._calibration)
            if best is not None and best[0].health.ok:
                break
        if best is None:
            self._calibration = saved
            return None
        attempt, self._calibration = best
        return attempt

    def _initialize_from(
        self, source, depth, intr, mask, full, pixels, points, graph
    ) -> _Attempt | None:
        """One initialization candidate from one label source."""
        if isinstance(source, str) and source == "geometric":
            labels, _ = geometric_labels(points)
        else:
            if source is self._get_forest():  # a forest (or stand-in) needs only predict
                voters = slice(None)
                label_img = np.asarray(source.predict(depth, mask, intr).labels)
                pix_labels = label_img[pixels[:, 0], pixels[:, 1]].astype(np.int64)
            else:
                # The net costs far more per pixel than the forest: every other row and
                # column votes (a quarter of the pixels, still several per point).
                voters = np.flatnonzero((pixels[:, 0] % 2 == 0) & (pixels[:, 1] % 2 == 0))
                probabilities = source.predict_pixels(depth, pixels[voters], intr, mask=mask)
                pix_labels = np.argmax(probabilities, axis=1).astype(np.int64)
            if np.count_nonzero(pix_labels >= 0) < self.min_points:
                return None
            labels = label_template_points(points, full[voters], pix_labels)
        labels = smooth_labels(labels, graph.rows, graph.cols)
        fresh_calibration = self._calibration is None
        if fresh_calibration:
            self._calibration = calibrate(
                points,
                labels,
                (graph.rows, graph.cols),
                full_points=full,
                height=self.height,
                truncated=bool(mask[0].any() or mask[-1].any()),
            )
        # Joints the labels do not support come from the last pose, moved with the body.
        guess = None
        if self._last_joints is not None:
            guess = self._last_joints + (points.mean(axis=0) - self._last_centre)
        if fresh_calibration:  # Where this person's arms put their shoulders.
            bare = self._fit(points, labels, graph, guess, anchor_shoulders=False)
            shoulders = measure_shoulders(bare.fit.joints, self._calibration.height)
            self._calibration = replace(self._calibration, shoulders=shoulders)
        attempt = self._fit(points, labels, graph, guess)
        if fresh_calibration and not attempt.health.ok:
            # Keep no calibration from a frame that could not be fitted.
            cal, self._calibration = self._calibration, None
            attempt = self._fit_with(cal, points, labels, graph)
            return attempt
        if not np.isfinite(attempt.fit.joints).all():
            return attempt
        cal = self._calibration
        anchors = bone_anchors(attempt.fit.joints, cal.bone_lengths)
        if fresh_calibration:
            reach = measure_reach(graph, points, labels, anchors, height=cal.height)
            self._calibration = cal = replace(cal, reach=reach)
        if self.relabel:  # Clean the forest's labels with Algorithm 2 and refit.
            labels2 = relabel(
                points,
                labels,
                anchors,
                height=cal.height,
                ratios=cal.reach,
                alpha=self.alpha,
                graph=graph,
            )
            again = self._fit(points, labels2, graph, guess)
            if again.health.score <= attempt.health.score:
                attempt = again
        if fresh_calibration:  # The world's up, for a camera that looks down or up.
            floor = None if self._floor is None else self._floor[0]
            up = world_up(attempt.fit.joints, floor_normal=floor)
            self._calibration = replace(self._calibration, up=up)
        return attempt
