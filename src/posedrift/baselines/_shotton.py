"""Shotton et al. 2011, per frame: forest labels, weighted mean-shift proposals, skeleton.

Shotton, Fitzgibbon, Cook, Sharp, Finocchio, Moore, Kipman and Blake, "Real-time
human pose recognition in parts from single depth images", CVPR 2011,
doi:10.1109/CVPR.2011.5995316.

Every frame on its own: the person is segmented, the shared body-part forest gives
``P(part | pixel)``, and each part's proposal is the mode of a Gaussian mean shift
over the part's pixels reprojected to 3-D, each weighted by
``P(part | pixel) d(pixel)^2`` (the pixel's surface area), over pixels whose
probability exceeds a threshold. Joints then come from the same skeleton fitting as
the tracker (:func:`posedrift.skeleton._fit.fit_skeleton`: part boundaries, part
axes oriented by the modes, bone lengths), which pushes the modes back along the
camera ray by each part's radius (Shotton's single push-back of about 4 cm, made
per part; :func:`shotton_proposals` gives the single-distance form), with the bone
lengths measured on the first frame by the tracker's own calibration. Where a
joint has no support in a frame's labels (an upper arm hidden behind its
forearm), the last frame's joint stands in, as a per-frame system's output
would hold it; nothing else is carried from frame to frame.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from posedrift._validation import check_scalar
from posedrift.baselines._common import calibrate_bones, label_frame, resolve_forest
from posedrift.camera import DepthFrame, Intrinsics
from posedrift.tracking import FrameResult, FrameStatus


def shotton_proposals(
    points: np.ndarray,
    probabilities: np.ndarray,
    *,
    bandwidth: float = 0.065,
    threshold: float = 0.14,
    push_back: float = 0.04,
) -> tuple[np.ndarray, np.ndarray]:
    """Per-part mean-shift proposals, weighted by ``P(part | pixel) z^2``, pushed back.

    Parameters
    ----------
    points : (N, 3) float
        Pixels reprojected to the camera frame, metres.
    probabilities : (N, P) float
        ``P(part | pixel)``.
    bandwidth : float
        Gaussian kernel width (metres).
    threshold : float
        Pixels with ``P(part | pixel)`` below it do not vote for that part.
    push_back : float
        Metres the surface mode moves away from the camera along its ray.

    Returns
    -------
    proposals : (P, 3) float
        Pushed-back modes; NaN for parts without votes.
    surface_modes : (P, 3) float
        The modes before the push-back.

    Examples
    --------
    >>> import numpy as np
    >>> pts = np.array([[0.0, 0.0, 2.0], [0.01, 0.0, 2.0]])
    >>> prob = np.array([[1.0, 0.0], [1.0, 0.0]])
    >>> np.round(shotton_proposals(pts, prob, push_back=0.04)[0], 3)
    array([[0.005, 0.   , 2.04 ],
           [  nan,   nan,   nan]])
    """
    from posedrift.skeleton._meanshift import part_modes

    points = np.asarray(points, dtype=float)
    probabilities = np.asarray(probabilities, dtype=float)
    n_parts = probabilities.shape[1]
    vote_pixel, vote_part = np.nonzero(probabilities >= threshold)
    weights = probabilities[vote_pixel, vote_part] * points[vote_pixel, 2] ** 2
    modes = part_modes(
        points[vote_pixel], vote_part, bandwidth=bandwidth, weights=weights, n_parts=n_parts
    )
    norm = np.linalg.norm(modes, axis=1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        pushed = modes + push_back * modes / norm
    return pushed, modes


class ShottonBaseline:
    """Shotton et al. 2011 per frame (a :class:`posedrift.tracking.PoseMethod`).

    Parameters
    ----------
    intrinsics : Intrinsics
    forest : BodyPartForest, optional
        The shared body-part forest (the default model when None).
    bandwidth : float
        Mean-shift kernel width, metres. 0.09 was best of 0.05, 0.065, 0.09 on the
        development clips 002_05 and 002_08 (200 frames each; 15.3 against 15.6
        degrees at Shotton's 0.065); the threshold (0.1 to 0.3) changed little.
    threshold : float
        Probability threshold of the votes (and of a pixel's label).
    stride : int
        Keep every ``stride``-th labelled pixel in the returned points.
    """

    name = "shotton"

    def __init__(
        self,
        intrinsics: Intrinsics,
        *,
        forest: Any = None,
        bandwidth: float = 0.09,
        threshold: float = 0.14,
        stride: int = 4,
    ) -> None:
        self.intrinsics = intrinsics
        self.forest = resolve_forest(forest)
        self.bandwidth = check_scalar(bandwidth, "bandwidth", low=0.0, caller="ShottonBaseline")
        self.threshold = check_scalar(
            threshold, "threshold", low=0.0, high=1.0, include_low=True, caller="ShottonBaseline"
        )
        self.stride = int(check_scalar(stride, "stride", low=1, include_low=True, integer=True))
        self.stature_: float | None = None
        self.bone_lengths_: np.ndarray | None = None
        self._last: np.ndarray | None = None

    def reset(self, intrinsics: Intrinsics) -> None:
        """Forget the stature and the last joints of the previous sequence."""
        self.intrinsics = intrinsics
        self.stature_ = None
        self.bone_lengths_ = None
        self._last = None

    def process(self, frame: DepthFrame) -> FrameResult:
        """Joints of one frame, from that frame alone (and the first frame's stature)."""
        from posedrift.skeleton._fit import fit_skeleton, image_exits

        start = time.perf_counter()
        lab = label_frame(frame, self.forest, threshold=self.threshold)
        t_label = time.perf_counter()
        if lab is None:
            return FrameResult.empty(
                frame.index, FrameStatus.NO_PERSON, "no person found", timestamp=frame.timestamp
            )
        if self.bone_lengths_ is None:
            self.stature_, self.bone_lengths_ = calibrate_bones(lab, frame.depth.shape[0])
        # The skeleton fitting pushes each part's mode back by that part's radius (the
        # per-part form of Shotton's push-back): hand it the surface modes.
        _, modes = shotton_proposals(
            lab.points,
            lab.probabilities,
            bandwidth=self.bandwidth,
            threshold=self.threshold,
            push_back=0.0,
        )
        fit = fit_skeleton(
            lab.points,
            lab.labels,
            bone_lengths=self.bone_lengths_,
            edges=lab.edges,
            modes=modes,
            prediction=self._last,
            exits=image_exits(lab.points, lab.labels, frame.intrinsics),
        )
        if np.isfinite(fit.joints).all():
            self._last = fit.joints
        end = time.perf_counter()
        keep = slice(None, None, self.stride)
        labelled = lab.labels[keep] >= 0
        if not np.isfinite(fit.joints).all():
            status, message = FrameStatus.LOST, "some joints have no support in the labels"
        else:
            status, message = FrameStatus.REINITIALIZED, ""
        return FrameResult(
            index=frame.index,
            status=status,
            joints=fit.joints,
            confidence=fit.confidence,
            points=lab.points[keep][labelled],
            labels=lab.labels[keep][labelled],
            timestamp=frame.timestamp,
            timings_ms={
                "labels": 1000 * (t_label - start),
                "skeleton": 1000 * (end - t_label),
            },
            message=message,
        )
