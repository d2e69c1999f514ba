"""Baselines of the paper's Table 1: Shotton et al. 2011, Dinh et al. 2014 (PDA), ICP tracking.

Each is a :class:`posedrift.tracking.PoseMethod` sharing the product's pipeline
pieces where the papers share them (segmentation, the body-part forest, the
skeleton fitting and the angles).
"""

from posedrift.baselines._common import LabelledPixels, estimate_stature, grid_edges, label_frame
from posedrift.baselines._icp import ICPTracker
from posedrift.baselines._pda import PDABaseline, pda_skeleton
from posedrift.baselines._shotton import ShottonBaseline, shotton_proposals

__all__ = [
    "ICPTracker",
    "LabelledPixels",
    "PDABaseline",
    "ShottonBaseline",
    "estimate_stature",
    "grid_edges",
    "label_frame",
    "pda_skeleton",
    "shotton_proposals",
]
