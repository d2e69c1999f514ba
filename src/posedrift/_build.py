"""Which optional compiled kernels this installation has (``setup.py`` builds them)."""

from __future__ import annotations

import importlib

KERNELS = (
    "posedrift.registration._cestep",
    "posedrift.labelling._ckernels",
    "posedrift.skeleton._cmeanshift",
    "posedrift.points._cpoints",
)
"""The C extensions; each has a NumPy twin that runs where it was not built."""


def compiled_kernels() -> dict[str, bool]:
    """Whether each optional compiled kernel is importable.

    An installation without a C compiler still works, on the NumPy twins (the same
    results, slower: ``docs/results-log.md``, speed section).

    Returns
    -------
    dict
        Module name -> importable.

    Examples
    --------
    >>> from posedrift import compiled_kernels
    >>> sorted(compiled_kernels())[0]
    'posedrift.labelling._ckernels'
    """
    out = {}
    for name in KERNELS:
        try:
            importlib.import_module(name)
        except ImportError:
            out[name] = False
        else:
            out[name] = True
    return out


def compiled_summary() -> str:
    """``"compiled kernels: all 4"``, or which are missing (for benchmark reports)."""
    have = compiled_kernels()
    missing = [name.removeprefix("posedrift.") for name, ok in have.items() if not ok]
    if not missing:
        return f"compiled kernels: all {len(have)}"
    kept = len(have) - len(missing)
    return f"compiled kernels: {kept} of {len(have)} (NumPy for {', '.join(missing)})"
