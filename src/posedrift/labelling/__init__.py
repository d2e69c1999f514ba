"""labelling"""

from posedrift.labelling._features import depth_features
from posedrift.labelling._forest import BodyPartForest, PartPrediction
from posedrift.labelling._net import BodyPartNet, FacingNets, fit_perceptron
from posedrift.labelling._votes import JointVotes, fit_joint_votes, joint_modes

__all__: list[str] = [
    "BodyPartForest",
    "BodyPartNet",
    "FacingNets",
    "JointVotes",
    "PartPrediction",
    "depth_features",
    "fit_joint_votes",
    "fit_perceptron",
    "joint_modes",
]

from posedrift.labelling._relabel import (
    GeodesicGraph,
    geodesic_distances,
    geodesic_graph,
    merge_islands,
    relabel,
)

__all__ += ["GeodesicGraph", "geodesic_distances", "geodesic_graph", "merge_islands", "relabel"]
