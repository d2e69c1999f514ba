"""ICP tracking: the tracker's loop with nearest-neighbour correspondences instead of CPD.

The paper's argument (Section 1) is that ICP-style registration, which pairs each
point with its nearest neighbour, falls into local optima on complex poses where
CPD's soft, coherent assignment does not. This baseline is the product's own
:class:`posedrift.tracking.PoseTracker` with ``correspondence="icp"``: everything
else (initialization, relabelling, mean shift, skeleton) is shared, so the
comparison isolates the correspondence model.
"""

from __future__ import annotations

from typing import Any

from posedrift.camera import DepthFrame, Intrinsics
from posedrift.tracking import FrameResult


class ICPTracker:
    """:class:`~posedrift.tracking.PoseTracker` with ICP correspondences, named ``"icp"``.

    Parameters
    ----------
    intrinsics : Intrinsics
    forest : BodyPartForest, optional
        The shared body-part forest (joint votes; pixel labels where there is no part net).
    **options
        Passed on to :class:`~posedrift.tracking.PoseTracker` (``part_net``, ``n_points``,
        ``relabel``, ``warm_start``, ``rng``...).
    """

    name = "icp"

    def __init__(self, intrinsics: Intrinsics, *, forest: Any = None, **options: Any) -> None:
        from posedrift.tracking import PoseTracker

        self.tracker = PoseTracker(intrinsics, forest=forest, correspondence="icp", **options)

    def reset(self, intrinsics: Intrinsics) -> None:
        """Forget the track."""
        self.tracker.reset(intrinsics)

    def process(self, frame: DepthFrame) -> FrameResult:
        """Track one frame."""
        return self.tracker.process(frame)
