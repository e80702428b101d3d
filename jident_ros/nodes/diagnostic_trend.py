"""The diagnostic node's trend of J1 and the backlash width (a mixin of
:class:`jident_ros.nodes.diagnostic.DiagnosticNode`): the tracker from the ``trend_*`` parameters and its state
file, each window's update (made by the node's :class:`~jident_ros.identify.monitor.DriveMonitor`) published on
``inertia_trend`` / ``backlash_width_trend`` and saved, and the "jident_diagnostic: trend" status
(:func:`jident_ros.identify.trend_status.trend_status`)."""
from __future__ import annotations

import math
import os
import stat
import time

from std_msgs.msg import Float64

from jident_ros.identify.levels import ERROR, OK
from jident_ros.identify.trend import TrendConfig, TrendStateError, TrendTracker
from jident_ros.identify.trend_status import trend_status


def _not_regular(path: str) -> str:
    """What ``path`` is when it exists and is not a regular file ("a FIFO", "a directory", ...), else ""."""
    try:
        mode = os.stat(path).st_mode
    except OSError:
        return ""
    if stat.S_ISREG(mode):
        return ""
    return {stat.S_IFIFO: "a FIFO", stat.S_IFDIR: "a directory", stat.S_IFCHR: "a character device",
            stat.S_IFBLK: "a block device", stat.S_IFSOCK: "a socket"}.get(stat.S_IFMT(mode), "not a file")


class TrendTask:
    """The trend's part of the diagnostic node (it sets ``trend``, ``trend_*`` counters and the publishers)."""

    # ----------------------------------------------------------------- trend
    def _start_trend(self):
        """A TrendTracker from the trend_* parameters; with trend_state_file, the saved state when there is
        one (a file that cannot be read is moved aside to <file>.corrupt-<UTC time> and the trend starts
        fresh: ERROR on the trend status, nothing overwritten)."""
        c = self.cfg
        config = TrendConfig.from_parameters(c)   # checked by validate()
        self.trend = TrendTracker(config)
        path = c["trend_state_file"]
        if not path:
            return
        path = os.path.expanduser(path)
        kind = _not_regular(path)
        if kind:   # a FIFO would block the read (and configure with it), a device or directory is not a state file
            self.trend_state_refused = True
            self.trend_error = (f"trend_state_file {path}: {kind}, not a regular file: not read, not written; "
                                "the trend runs without a state file")
            self.get_logger().error(self.trend_error)
            return
        try:
            # checked on load (identify/trend_state.py): J1 within the policy's plausible band of the nominal
            plausible = {"inertia_kgm2": self.policy.band_kgm2(self.nominal)}
            self.trend = TrendTracker.load(path, config, plausible)
            self.get_logger().info(f"trend state read from {path} ({self.trend.n_windows} window(s) so far)")
        except FileNotFoundError:
            self.get_logger().info(f"trend state file {path} does not exist yet: the trend starts fresh")
        except (TrendStateError, OSError) as exc:
            aside = f"{path}.corrupt-{time.strftime('%Y%m%dT%H%M%SZ', time.gmtime())}"
            try:
                os.replace(path, aside)
                kept = f"moved to {aside}"
            except OSError as mv:
                kept = f"could not be moved aside ({mv}); it will be overwritten"
            self.trend_error = f"trend state unusable: {exc}; {kept}; the trend started fresh"
            self.get_logger().error(self.trend_error)

    def _update_trend(self, win, result):
        """The tracker's update of one diagnosed window (the monitor made it): publish the smoothed J1 and
        width; save the state."""
        u, source = result.trend, result.trend_source
        if u is None:   # nothing to follow in this window (its status says why)
            self.trend_windows_without_estimate += 1
            return
        self.trend_width_source = source or "none"
        if source is not None:
            self.trend_width_sources[source] += 1
        self.trend_update = u
        if u.skipped:
            self.get_logger().warning(f"trend: window {win.window_id} skipped: {u.reason}",
                                      throttle_duration_sec=1.0)
            return
        for pub, name, value in ((self.pub_inertia_trend, "inertia_trend", u.inertia_kgm2),
                                 (self.pub_width_trend, "backlash_width_trend", u.width_m)):
            if pub is not None and value is not None and math.isfinite(value):
                m = Float64(data=float(value))
                pub.publish(m)
                self._record(name, m)
        for ev in u.changes:
            self.get_logger().warning(f"trend: change of {ev.quantity} detected at window {win.window_id}: "
                                      f"{ev.size_pct:+.2f} % (onset t = {ev.onset_time_s:.3f} s)")
        if self.cfg["trend_state_file"] and not getattr(self, "trend_state_refused", False):
            path = os.path.expanduser(self.cfg["trend_state_file"])
            try:
                self.trend.save(path)
                self.trend_saves += 1
                self.trend_save_error = None
            except (OSError, ValueError) as exc:
                self.trend_save_error = f"trend state not written to {path}: {exc}"
                self.get_logger().error(self.trend_save_error, throttle_duration_sec=10.0)

    def trend_task_status(self, stat):
        """"jident_diagnostic: trend": the tracker's level and one line with its numbers
        (:func:`jident_ros.identify.trend_status.trend_status`); ERROR when its state file was unusable
        (a fresh start) or cannot be written."""
        if not self.cfg["trend_enabled"]:
            stat.summary(OK, "trend off (trend_enabled is false)")
            return stat
        if self.trend is None:
            stat.summary(OK, "trend not started yet (node not configured)")
            return stat
        u = self.trend_update
        if u is None:
            level, message, values = OK, "no window with a J1 or width estimate yet", []
        else:
            level, message, values = trend_status(u)
        problems = [p for p in (self.trend_error, self.trend_save_error) if p]
        if problems:
            level, message = ERROR, "; ".join(problems) + f"; {message}"
        stat.summary(level, message)
        for k, v in values:
            stat.add(k, v)
        for k, v in (("windows_updated", self.trend.n_windows),
                     ("windows_without_estimate", self.trend_windows_without_estimate),
                     ("width_source", self.trend_width_source),
                     ("width_from_flank_detector", self.trend_width_sources["flank"]),
                     ("width_from_gap_estimator", self.trend_width_sources["gap"]),
                     ("state_file", self.cfg["trend_state_file"]), ("state_saves", self.trend_saves)):
            stat.add(k, v)
        return stat


__all__ = ["TrendTask"]
