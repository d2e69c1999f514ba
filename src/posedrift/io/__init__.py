"""Inputs and outputs: depth recordings in, poses, BVH and point clouds out."""

from posedrift.io._bvh_export import bvh_to_camera, camera_to_bvh, write_bvh
from posedrift.io._readers import (
    DEPTH_SCALES,
    DepthSource,
    UnreadableFrame,
    open_depth_source,
    resolve_depth_scale,
    resolve_intrinsics,
)
from posedrift.io._writers import (
    CSV_COLUMNS,
    read_point_cloud,
    read_poses,
    write_point_clouds,
    write_poses,
)

__all__ = [
    "CSV_COLUMNS",
    "DEPTH_SCALES",
    "DepthSource",
    "UnreadableFrame",
    "bvh_to_camera",
    "camera_to_bvh",
    "open_depth_source",
    "read_point_cloud",
    "read_poses",
    "resolve_depth_scale",
    "resolve_intrinsics",
    "write_bvh",
    "write_point_clouds",
    "write_poses",
]
