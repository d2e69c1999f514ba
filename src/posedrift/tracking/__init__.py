"""The tracking loop that joins the stages, and what it returns per frame."""

from posedrift.tracking._result import FrameResult, FrameStatus, PoseMethod

__all__ = ["FrameResult", "FrameStatus", "PoseMethod"]
