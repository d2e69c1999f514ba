"""Pictures of the pipeline: label maps, side-by-side video, angle plots, a 3-D viewer."""

from posedrift.visualization._body import render_posed_body
from posedrift.visualization._draw import (
    LABEL_LUT,
    depth_image,
    draw_label_image,
    draw_points_image,
    draw_skeleton,
    frame_panels,
    write_depth_video,
    write_video,
)
from posedrift.visualization._plots import plot_angles
from posedrift.visualization._viewer import DATA_ELEMENT_ID, viewer_data, write_viewer

__all__ = [
    "DATA_ELEMENT_ID",
    "LABEL_LUT",
    "depth_image",
    "draw_label_image",
    "draw_points_image",
    "draw_skeleton",
    "frame_panels",
    "plot_angles",
    "render_posed_body",
    "viewer_data",
    "write_depth_video",
    "write_video",
    "write_viewer",
]
