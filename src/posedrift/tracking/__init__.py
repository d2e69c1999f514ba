"""The tracking loop that joins the stages, and what it returns per frame."""

from posedrift.tracking._result import FrameResult, FrameStatus, PoseMethod
from posedrift.tracking._smoothing import LiveSmoother, smooth_results

__all__ = ["FrameResult", "FrameStatus", "LiveSmoother", "PoseMethod", "smooth_results"]

from posedrift.tracking._health import Health, assess
from posedrift.tracking._init import Calibration, calibrate, level_rotation, world_up
from posedrift.tracking._tracker import PoseTracker, working_decimation

__all__ += ["Calibration", "Health", "PoseTracker", "assess", "calibrate", "working_decimation"]
__all__ += ["level_rotation", "world_up"]
