"""The 15-joint skeleton, the 15 body parts, and the eight joint angles."""

from posedrift.skeleton._angles import (
    ANGLE_JOINTS,
    angles_dict,
    facing_yaw,
    joint_angles,
    pelvis_centre,
)
from posedrift.skeleton._convention import (
    CONVENTIONS,
    body_frame,
    fit_convention,
    to_convention,
)
from posedrift.skeleton._definitions import (
    ANGLE_NAMES,
    EXTRA_POINT_NAMES,
    JOINT_INDEX,
    JOINT_NAMES,
    JOINT_PARENTS,
    PART_COLOURS,
    PART_INDEX,
    PART_JOINTS,
    PART_NAMES,
    SEGMENT_RATIOS,
    other_side,
)
from posedrift.skeleton._smooth import smooth_joints
from posedrift.skeleton._tpose import t_pose_joints

__all__ = [
    "ANGLE_JOINTS",
    "ANGLE_NAMES",
    "CONVENTIONS",
    "EXTRA_POINT_NAMES",
    "JOINT_INDEX",
    "JOINT_NAMES",
    "JOINT_PARENTS",
    "PART_COLOURS",
    "PART_INDEX",
    "PART_JOINTS",
    "PART_NAMES",
    "SEGMENT_RATIOS",
    "angles_dict",
    "body_frame",
    "facing_yaw",
    "fit_convention",
    "joint_angles",
    "other_side",
    "pelvis_centre",
    "smooth_joints",
    "t_pose_joints",
    "to_convention",
]

from posedrift.skeleton._fit import (
    SkeletonFit,
    bone_anchors,
    fit_skeleton,
    image_exits,
    part_anchors,
    prior_bone_lengths,
    refine_with_votes,
)
from posedrift.skeleton._meanshift import part_modes

__all__ += [
    "SkeletonFit",
    "bone_anchors",
    "fit_skeleton",
    "image_exits",
    "part_anchors",
    "part_modes",
    "prior_bone_lengths",
    "refine_with_votes",
]
