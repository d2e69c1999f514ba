"""registration: Coherent Point Drift (rigid, affine, nonrigid)."""

from posedrift.registration._cpd import register_affine, register_nonrigid, register_rigid
from posedrift.registration._result import ConvergenceWarning, CPDResult

__all__: list[str] = [
    "CPDResult",
    "ConvergenceWarning",
    "register_affine",
    "register_nonrigid",
    "register_rigid",
]
