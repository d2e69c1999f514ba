"""labelling"""

from posedrift.labelling._features import depth_features
from posedrift.labelling._forest import BodyPartForest, PartPrediction

__all__: list[str] = [
    "BodyPartForest",
    "PartPrediction",
    "depth_features",
]

from posedrift.labelling._relabel import (
    GeodesicGraph,
    geodesic_distances,
    geodesic_graph,
    relabel,
)

__all__ += ["GeodesicGraph", "geodesic_distances", "geodesic_graph", "relabel"]
