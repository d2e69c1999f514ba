"""A canonical T-pose from anthropometric ratios: a reference for tests and priors."""

from __future__ import annotations

import numpy as np

from posedrift.skeleton._definitions import JOINT_INDEX, JOINT_NAMES, SEGMENT_RATIOS


def t_pose_joints(height: float = 1.75) -> np.ndarray:
    """The 15 joints of a person of stature ``height`` standing in a T-pose.

    Body frame: metres, origin on the floor between the feet, +Y up, +X to the
    person's left, +Z the direction the person faces. Arms horizontal, legs
    straight, feet below the hips.

    Parameters
    ----------
    height : float
        Stature H in metres.

    Returns
    -------
    joints : (15, 3) float
    """
    r = SEGMENT_RATIOS
    h = float(height)
    shoulder_y = r["shoulder_height"] * h
    hip_y = r["hip_height"] * h
    half_shoulder = 0.5 * r["shoulder_width"] * h
    half_hip = 0.5 * r["hip_width"] * h
    knee_y = hip_y - r["thigh"] * h
    ankle_y = r["ankle_height"] * h
    neck_y = shoulder_y + r["neck_above_shoulders"] * h
    head_y = h - 0.5 * r["head_height"] * h
    joints = np.zeros((len(JOINT_NAMES), 3))
    place = {
        "head": (0.0, head_y),
        "neck": (0.0, neck_y),
        "left_shoulder": (half_shoulder, shoulder_y),
        "right_shoulder": (-half_shoulder, shoulder_y),
        "left_elbow": (half_shoulder + r["upper_arm"] * h, shoulder_y),
        "right_elbow": (-half_shoulder - r["upper_arm"] * h, shoulder_y),
        "left_hand": (half_shoulder + (r["upper_arm"] + r["forearm"]) * h, shoulder_y),
        "right_hand": (-half_shoulder - (r["upper_arm"] + r["forearm"]) * h, shoulder_y),
        "left_hip": (half_hip, hip_y),
        "right_hip": (-half_hip, hip_y),
        "left_knee": (half_hip, knee_y),
        "right_knee": (-half_hip, knee_y),
        "left_foot": (half_hip, ankle_y),
        "right_foot": (-half_hip, ankle_y),
    }
    for name, (x, y) in place.items():
        joints[JOINT_INDEX[name]] = (x, y, 0.0)
    pelvis_y = hip_y
    joints[JOINT_INDEX["torso"]] = (0.0, 0.5 * (neck_y + pelvis_y), 0.0)
    return joints
