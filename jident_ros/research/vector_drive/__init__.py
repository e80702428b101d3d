"""A third validation drive model (issue 20 item 6): motulator's induction machine under motulator's own
current-vector control and speed PI, a two-mass coupling with a backlash dead zone and bearing friction;
recordings as a real drive makes them (docs/vector_drive.md).  Research/validation code: the runtime never
imports it.  motulator is an optional dependency (``pip install -e '.[zoo]'``).
"""
from .model import (
           EVENTS,
           TRAVERSING_EVENTS,
           Controller,
           DriveParams,
           Machine,
           Mechanics,
           Scenario,
           motulator_available,
           scenario,
           simulate,
           small_drive,
)

__all__ = ["EVENTS", "TRAVERSING_EVENTS", "Controller", "DriveParams", "Machine", "Mechanics", "Scenario",
           "motulator_available", "scenario", "simulate", "small_drive"]
