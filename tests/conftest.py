"""Shared fixtures: the development data, found beside the checkout or through an env var."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

_DEFAULT = Path(__file__).resolve().parents[1].parent / "shared" / "data"


def shared_data_root() -> Path | None:
    """``$POSEDRIFT_DATA`` or ``../shared/data`` beside the checkout, if present."""
    root = Path(os.environ.get("POSEDRIFT_DATA", _DEFAULT))
    return root if root.is_dir() else None


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """The development data folder; skips the test with a clear message when absent."""
    root = shared_data_root()
    if root is None:
        pytest.skip(f"development data not found at {_DEFAULT} (set POSEDRIFT_DATA to its folder)")
    return root


@pytest.fixture(scope="session")
def mocap_dir(shared_data: Path) -> Path:
    """``shared/data/mocap``."""
    return shared_data / "mocap"


@pytest.fixture(scope="session")
def utd_dir(shared_data: Path) -> Path:
    """``shared/data/utd-mhad`` (holds ``Depth/`` and ``Skeleton/``)."""
    return shared_data / "utd-mhad"


@pytest.fixture(params=["compiled", "numpy"])
def meanshift_kernel(request, monkeypatch) -> str:
    """Run a test with the compiled mean shift (where built) and again with its NumPy twin."""
    from posedrift.skeleton import _meanshift

    if request.param == "compiled" and _meanshift._cmeanshift is None:
        pytest.skip("the compiled mean shift (posedrift.skeleton._cmeanshift) is not built")
    if request.param == "numpy":
        monkeypatch.setattr(_meanshift, "_cmeanshift", None)
    return request.param
