"""synthetic"""

from posedrift.synthetic._body import BodyModel
from posedrift.synthetic._folder import contact_sheet, read_synthetic, write_synthetic
from posedrift.synthetic._noise import kinect_noise
from posedrift.synthetic._render import Render, Scene, depth_to_mm, plane_depth, render
from posedrift.synthetic._sequence import build_sequence, place_camera
from posedrift.synthetic._bvh import BvhData, load_bvh, parse_bvh
from posedrift.synthetic._motion import Motion, bvh_motion, is_t_pose, with_calibration_pose
from posedrift.synthetic._procedural import procedural_motion
from posedrift.synthetic._rigs import RIGS, RigMap

__all__: list[str] = [
    "BodyModel",
    "Render",
    "Scene",
    "build_sequence",
    "contact_sheet",
    "depth_to_mm",
    "kinect_noise",
    "place_camera",
    "plane_depth",
    "read_synthetic",
    "render",
    "write_synthetic",
    "BvhData",
    "Motion",
    "RIGS",
    "RigMap",
    "bvh_motion",
    "is_t_pose",
    "load_bvh",
    "parse_bvh",
    "procedural_motion",
    "with_calibration_pose",
]
