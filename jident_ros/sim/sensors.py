"""Sensors specified in physical terms (issue 13 item 4): what a real drive's measurements look like.

MATLAB's ``awgn(x, snr, 'measured')`` (:func:`jident_ros.sim.add_measurement_noise`) scales the noise with
each signal's mean square over the window, so at 30 dB the rotor speed (~150 rad/s) gets ~4.7 rad/s rms,
unlike any encoder or torque estimate.  A :class:`SensorSpec` instead gives every sensor the numbers of a
datasheet; :func:`apply_sensors` turns noise-free windows into what those sensors would have recorded.

The default set (:data:`DEFAULT_SENSORS`; docs/model.md, "Sensors") is built from typical datasheet
values of each sensor class, not from one particular part:

* motor and load-side encoders: 16-bit absolute, 2^16 counts per revolution;
* rotor and wheel speed from the drive's speed estimate: 0.02 rad/s rms (0.013 % of 150 rad/s);
* electromagnetic torque from the drive's torque estimate: 0.5 % of rated torque rms, rated torque = the
  per-unit base torque M_b (212 N m): 1.06 N m;
* accelerometers (a1 at the wheel circumference, a2 on the mass): MEMS class, 200 ug/sqrt(Hz)
  (1.96e-3 m/s^2/sqrt(Hz)), +-16 g range, noise band = the Nyquist band of the sampling (1 kHz at
  T_s = 0.5 ms): 0.062 m/s^2 rms; readings beyond the range are clipped;
* mass speed v2 from a measuring wheel: 0.005 m/s rms (0.03 % of 15 m/s).
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from jident_ros.sim.simulate import WindowSet, quantise_encoders

STANDARD_GRAVITY_M_S2 = 9.80665


@dataclass(frozen=True)
class SensorSpec:
    """Every measured channel's sensor, in physical terms (0 = a perfect sensor for that channel).

    Attributes
    ----------
    encoder_counts_per_rev : int
        Resolution of the encoders on alpha1 and alpha2, counts per revolution (0: exact angles).
    speed_noise_rad_s : float
        White noise on omega1 and omega2, rad/s rms.
    torque_noise_pct_rated : float
        White noise on m_el, % of the rated torque, rms.
    rated_torque_nm : float
        Rated torque, N m (0: the model's per-unit base torque M_b).
    accelerometer_noise_density_m_s2_rthz : float
        Noise density of the accelerometers on a1 and a2, m/s^2/sqrt(Hz).
    accelerometer_range_m_s2 : float
        Full-scale range of the accelerometers, +- m/s^2 (0: unlimited); readings are clipped to it.
    accelerometer_bandwidth_hz : float
        Noise band of the accelerometers, Hz (0: the Nyquist band 1/(2 T_s)).
    line_speed_noise_m_s : float
        White noise on the mass speed v2, m/s rms.
    """

    encoder_counts_per_rev: int = 2 ** 16
    speed_noise_rad_s: float = 0.02
    torque_noise_pct_rated: float = 0.5
    rated_torque_nm: float = 0.0
    accelerometer_noise_density_m_s2_rthz: float = 200e-6 * STANDARD_GRAVITY_M_S2
    accelerometer_range_m_s2: float = 16 * STANDARD_GRAVITY_M_S2
    accelerometer_bandwidth_hz: float = 0.0
    line_speed_noise_m_s: float = 0.005

    def __post_init__(self):
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v < 0:
                raise ValueError(f"SensorSpec.{f.name}: must be a finite number >= 0, got {v!r}")

    def scaled(self, factor: float) -> "SensorSpec":
        """Every noise level times ``factor`` (the encoder and the accelerometer range unchanged)."""
        return dataclasses.replace(
            self, speed_noise_rad_s=self.speed_noise_rad_s * factor,
            torque_noise_pct_rated=self.torque_noise_pct_rated * factor,
            accelerometer_noise_density_m_s2_rthz=self.accelerometer_noise_density_m_s2_rthz * factor,
            line_speed_noise_m_s=self.line_speed_noise_m_s * factor)

    def noise_rms(self, sample_period_s: float, base_torque_nm: float) -> dict:
        """Noise rms per channel in SI units at this sample period."""
        band = self.accelerometer_bandwidth_hz or 0.5 / sample_period_s
        acc = self.accelerometer_noise_density_m_s2_rthz * math.sqrt(band)
        rated = self.rated_torque_nm or base_torque_nm
        return {"omega1": self.speed_noise_rad_s, "omega2": self.speed_noise_rad_s,
                "m_el": self.torque_noise_pct_rated / 100.0 * rated, "a1": acc, "a2": acc,
                "v2": self.line_speed_noise_m_s}

    def describe(self, sample_period_s: float, base_torque_nm: float) -> str:
        """One line in physical terms (for reports)."""
        rms = self.noise_rms(sample_period_s, base_torque_nm)
        enc = (f"encoders 2^{math.log2(self.encoder_counts_per_rev):.3g} counts/rev"
               if self.encoder_counts_per_rev else "exact angles")
        rng = (f", ±{self.accelerometer_range_m_s2 / STANDARD_GRAVITY_M_S2:.3g} g"
               if self.accelerometer_range_m_s2 else "")
        return (f"{enc}; speed {self.speed_noise_rad_s:.3g} rad/s rms; torque estimate "
                f"{self.torque_noise_pct_rated:.3g} % of rated ({rms['m_el']:.3g} N m rms); accelerometers "
                f"{self.accelerometer_noise_density_m_s2_rthz / STANDARD_GRAVITY_M_S2 * 1e6:.3g} µg/√Hz "
                f"({rms['a1']:.3g} m/s² rms){rng}; v2 {self.line_speed_noise_m_s:.3g} m/s rms")


#: The documented default sensor set (module docstring).
DEFAULT_SENSORS = SensorSpec()


def apply_sensors(windows: WindowSet, spec: SensorSpec, seed: int, base_torque_nm: float) -> WindowSet:
    """What the sensors of ``spec`` would have recorded of noise-free ``windows`` (seeded).

    ``base_torque_nm``: the model's per-unit base torque M_b (``MotorParams.base.torque_nm``), the rated
    torque when ``spec.rated_torque_nm`` is 0."""
    rng = np.random.default_rng(seed)
    rms = spec.noise_rms(windows.sample_period_s, base_torque_nm)
    sig = dict(windows.signals)
    for ch in ("a1", "m_el", "omega1", "a2", "v2", "omega2"):
        if ch not in sig:
            continue
        x = sig[ch] + rng.standard_normal(sig[ch].shape) * rms[ch]
        if ch in ("a1", "a2") and spec.accelerometer_range_m_s2:
            x = np.clip(x, -spec.accelerometer_range_m_s2, spec.accelerometer_range_m_s2)
        sig[ch] = x
    out = WindowSet(windows.t, sig, windows.cases, windows.entry_index, windows.sample_period_s,
                    windows.initial_slip, dict(windows.metadata, sensors=dataclasses.asdict(spec), seed=seed))
    if spec.encoder_counts_per_rev:
        out = quantise_encoders(out, int(spec.encoder_counts_per_rev))
        out.metadata.update(sensors=dataclasses.asdict(spec), seed=seed)
    return out
