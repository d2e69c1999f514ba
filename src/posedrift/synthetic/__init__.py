"""synthetic"""

from posedrift.synthetic._body import BodyModel
from posedrift.synthetic._bvh import BvhData, load_bvh, parse_bvh
from posedrift.synthetic._folder import contact_sheet, read_synthetic, write_synthetic
from posedrift.synthetic._motion import Motion, bvh_motion, is_t_pose, with_calibration_pose
from posedrift.synthetic._noise import kinect_noise
from posedrift.synthetic._procedural import procedural_motion
from posedrift.synthetic._render import Render, Scene, depth_to_mm, plane_depth, render
from posedrift.synthetic._rigs import RIGS, RigMap
from posedrift.synthetic._sequence import build_sequence, place_camera

__all__: list[str] = [
    "RIGS",
    "BodyModel",
    "BvhData",
    "Motion",
    "Render",
    "RigMap",
    "Scene",
    "build_sequence",
    "bvh_motion",
    "contact_sheet",
    "depth_to_mm",
    "is_t_pose",
    "kinect_noise",
    "load_bvh",
    "parse_bvh",
    "place_camera",
    "plane_depth",
    "procedural_motion",
    "read_synthetic",
    "render",
    "with_calibration_pose",
    "write_synthetic",
]
