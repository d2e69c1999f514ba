"""The skeleton, the body parts and the angles: one definition for the whole product.

See ``METHOD.md`` section 2. Joints follow the ITOP / OpenNI 15-joint order;
right and left are the person's own.
"""

from __future__ import annotations

from types import MappingProxyType

JOINT_NAMES: tuple[str, ...] = (
    "head",
    "neck",
    "right_shoulder",
    "left_shoulder",
    "right_elbow",
    "left_elbow",
    "right_hand",
    "left_hand",
    "torso",
    "right_hip",
    "left_hip",
    "right_knee",
    "left_knee",
    "right_foot",
    "left_foot",
)
"""The 15 joints in output order. ``hand`` is the wrist, ``foot`` the ankle."""

JOINT_INDEX = MappingProxyType({name: i for i, name in enumerate(JOINT_NAMES)})

JOINT_PARENTS: tuple[int, ...] = (1, 8, 1, 1, 2, 3, 4, 5, -1, 8, 8, 9, 10, 11, 12)
"""Kinematic tree over the 15 joints, rooted at ``torso`` (-1 marks the root)."""

PART_NAMES: tuple[str, ...] = (
    "head",
    "upper_torso",
    "lower_torso",
    "right_upper_arm",
    "left_upper_arm",
    "right_forearm",
    "left_forearm",
    "right_hand",
    "left_hand",
    "right_thigh",
    "left_thigh",
    "right_shank",
    "left_shank",
    "right_foot",
    "left_foot",
)
"""The 15 body parts (segments). Label maps store ``part index + 1``, 0 for background."""

PART_INDEX = MappingProxyType({name: i for i, name in enumerate(PART_NAMES)})


def other_side(name: str) -> str:
    """The left joint or part for a right one and the other way round; others as given.

    >>> other_side("left_elbow"), other_side("right_forearm"), other_side("head")
    ('right_elbow', 'left_forearm', 'head')
    """
    if name.startswith("left_"):
        return "right_" + name[5:]
    if name.startswith("right_"):
        return "left_" + name[6:]
    return name


PART_COLOURS: tuple[tuple[int, int, int], ...] = (
    (230, 25, 75),  # head: red
    (60, 180, 75),  # upper_torso: green
    (0, 130, 200),  # lower_torso: blue
    (245, 130, 48),  # right_upper_arm: orange
    (145, 30, 180),  # left_upper_arm: purple
    (255, 225, 25),  # right_forearm: yellow
    (70, 240, 240),  # left_forearm: cyan
    (240, 50, 230),  # right_hand: magenta
    (210, 245, 60),  # left_hand: lime
    (250, 190, 212),  # right_thigh: pink
    (0, 128, 128),  # left_thigh: teal
    (170, 110, 40),  # right_shank: brown
    (220, 190, 255),  # left_shank: lavender
    (128, 0, 0),  # right_foot: maroon
    (0, 0, 128),  # left_foot: navy
)
"""One fixed RGB colour per part, used by every label map the product draws."""

PART_JOINTS: tuple[tuple[str, str], ...] = (
    ("neck", "head"),
    ("neck", "torso"),
    ("torso", "pelvis"),
    ("right_shoulder", "right_elbow"),
    ("left_shoulder", "left_elbow"),
    ("right_elbow", "right_hand"),
    ("left_elbow", "left_hand"),
    ("right_hand", "right_hand_tip"),
    ("left_hand", "left_hand_tip"),
    ("right_hip", "right_knee"),
    ("left_hip", "left_knee"),
    ("right_knee", "right_foot"),
    ("left_knee", "left_foot"),
    ("right_foot", "right_toe"),
    ("left_foot", "left_toe"),
)
"""Proximal and distal end of each part. ``pelvis`` is the mean of the hips; tips and
toes are extra points that a rig may give and the skeleton may extrapolate."""

EXTRA_POINT_NAMES: tuple[str, ...] = (
    "head_top",
    "right_hand_tip",
    "left_hand_tip",
    "right_toe",
    "left_toe",
)
"""Points beyond the 15 joints that rigs may give (used to pose the body model)."""

ANGLE_NAMES: tuple[str, ...] = (
    "left_elbow",
    "right_elbow",
    "left_shoulder",
    "right_shoulder",
    "left_knee",
    "right_knee",
    "left_hip",
    "right_hip",
)
"""The eight angles of the paper's Table 1, in its column order."""

SEGMENT_RATIOS = MappingProxyType(
    {
        "upper_arm": 0.186,
        "forearm": 0.146,
        "hand": 0.108,
        "thigh": 0.245,
        "shank": 0.246,
        "foot_length": 0.152,
        "ankle_height": 0.039,
        "shoulder_width": 0.259,
        "hip_width": 0.191,
        "hip_height": 0.530,
        "shoulder_height": 0.818,
        "neck_above_shoulders": 0.02,
        "head_height": 0.130,
    }
)
"""Segment lengths as fractions of stature H (Drillis & Contini 1966, after Winter).

Priors only: a person's own lengths come from initialization."""
