"""A second, independent drive model for validation (issue 12 part 5).

Vector-controlled 30 kW induction motor, jaw coupling with Hertz/Hunt-Crossley
backlash contact, optional gearbox, belt conveyor; entries from speed-reference
steps.  It shares no code with ``jident_ros.sim``.  See docs/second_drive.md.
"""
from .model import PAPER_INERTIAS_KGM2, PAPER_WIDTHS_M, Drive, DriveParams, Result, gaps, simulate

__all__ = ["PAPER_INERTIAS_KGM2", "PAPER_WIDTHS_M", "Drive", "DriveParams", "Result", "gaps", "simulate"]
