"""The record of a flank detector's window capture in progress (:class:`_FlankCapture`), shared by the detector
(:mod:`jident_ros.stream.flank`) and its method groups (:mod:`jident_ros.stream.flank_window`,
:mod:`jident_ros.stream.flank_scan`, :mod:`jident_ros.stream.flank_refine`).
"""
from __future__ import annotations

from dataclasses import dataclass, field


@dataclass
class _FlankCapture:
    rows: list                 # arrays of rows from (departure - samples_before_entry) on
    count: int
    departure_row: int         # row of the departure sample inside the capture
    flank_rad: float           # the entry flank's level (delta)
    flank_sigma_rad: float
    second_entry_rows: list = field(default_factory=list)   # departures seen while capturing (capture rows)
    skip: bool = False         # short history: the transient is skipped, not captured
    pending: bool = False      # an entry inside another window: its own window only once its excursion ends on the
                               # other flank (a traversal), decided at the next contact
    start_row: int = 0         # stream row of the capture's first row
    returning: bool = False    # a traversal back inside another window (its flank: the other window's re-contact)
    after_row: int = -1        # a crossing after a bounce (REBOUND_*): its entry must lie after this stream row ...
    turn_row: int = -1         # ... and not before the bounce's re-contact (its deepest return, stream row); else at
    level_row: int = -1        # this stream row, where delta passes the window's entry level again (REBOUND_*)
    shallow: bool = False      # its excursion ended in a contact short of min_travel_rad (SHALLOW_*): a window only
                               # when it passed the zero-twist point, decided when it is complete
