"""The rig under program control: calibration captures through the projector window, and ``rig check``."""

from .capture import DEFAULT_COMB_STEP_ROWS, DEFAULT_FRAME_RATE_HZ, capture_comb
from .check import Check, check_rig

__all__ = ["DEFAULT_COMB_STEP_ROWS", "DEFAULT_FRAME_RATE_HZ", "Check", "capture_comb", "check_rig"]
