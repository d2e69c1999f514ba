"""Evaluation against ground truth or a reference: metrics, protocols, harness."""

from posedrift.evaluation._harness import (
    DEFAULT_METHODS,
    METHODS,
    VIEWS,
    EvaluationRun,
    MethodRun,
    evaluate,
    facing_by_view,
    make_method,
    mean_of_repeats,
    parse_methods,
    run_methods,
    summarize,
    unusable_reason,
)
from posedrift.evaluation._metrics import (
    angle_agreement,
    angle_errors,
    angles_in_view,
    failed_frames,
    fill_forward,
    joint_errors_m,
    map_at,
    mpjpe_mm,
)
from posedrift.evaluation._report import PAPER_TABLE1, markdown_table
from posedrift.evaluation._types import EvaluationSequence, Reference
from posedrift.evaluation._utd import (
    KINECT20_NAMES,
    KINECT20_TO_15,
    find_utd_sequences,
    kinect20_to_joints,
    load_utd_sequence,
)

__all__ = [
    "DEFAULT_METHODS",
    "KINECT20_NAMES",
    "KINECT20_TO_15",
    "METHODS",
    "PAPER_TABLE1",
    "VIEWS",
    "EvaluationRun",
    "EvaluationSequence",
    "MethodRun",
    "Reference",
    "angle_agreement",
    "angle_errors",
    "angles_in_view",
    "evaluate",
    "facing_by_view",
    "failed_frames",
    "fill_forward",
    "find_utd_sequences",
    "joint_errors_m",
    "kinect20_to_joints",
    "load_utd_sequence",
    "make_method",
    "map_at",
    "markdown_table",
    "mean_of_repeats",
    "mpjpe_mm",
    "parse_methods",
    "run_methods",
    "summarize",
    "unusable_reason",
]
