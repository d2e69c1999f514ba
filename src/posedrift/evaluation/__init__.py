"""Evaluation against ground truth or a reference: metrics, protocols, harness."""

from posedrift.evaluation._types import EvaluationSequence, Reference

__all__ = ["EvaluationSequence", "Reference"]
