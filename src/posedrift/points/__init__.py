"""points"""

from posedrift.points._humanoid import sample_humanoid

__all__: list[str] = []
__all__ += ["sample_humanoid"]

from posedrift.points._downsample import downsample  # noqa: E402
from posedrift.points._segment import BackgroundModel, fit_floor_plane, segment_person  # noqa: E402

__all__ += ["BackgroundModel", "downsample", "fit_floor_plane", "segment_person"]
