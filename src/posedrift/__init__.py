"""posedrift: 3-D human pose from depth frames on a CPU.

The pipeline follows the paper's nonrigid point-set registration and body-part
tracking: depth silhouette -> 3-D points -> part labels tracked by Coherent Point
Drift -> geodesic relabelling -> mean-shift joints -> skeleton -> joint angles.

Subpackages, one per stage of the data's way through the product:
``camera`` (intrinsics, depth frames), ``points`` (segmentation, downsampling),
``registration`` (CPD), ``labelling`` (forest, relabelling), ``skeleton``
(definitions, angles, joints), ``tracking`` (the loop), ``synthetic`` (motion
capture, body model, renderer), ``baselines``, ``evaluation``, ``io``,
``visualization`` and ``cli``.
"""

from posedrift._build import compiled_kernels

__version__ = "0.1.0"

__all__ = ["__version__", "compiled_kernels"]
