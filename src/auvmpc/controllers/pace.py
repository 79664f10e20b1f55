"""The speed a crippled vehicle flies its mission at: its level flight's, trimmed by the depth.

A torpedo with a jammed stern plane holds its depth at one speed only
(models/level_flight.py), and that speed is the controller's model's: the plant's differs by
the model's error (20 % of added mass and damping on the presets), and the current observer
takes up part of the surge's error as a current, so the speed flown through the water is off
by as much. Flown a little too fast the vehicle sinks (or climbs) steadily: the 5 deg jam of
remus100-stuck-fin, declared, drifted 0.3 m deep in 70 s at the model's 1.01 m/s.

So the pace is corrected by the depth error e = z - z_ref (down positive), a PI on the
quasi-steady depth rate e' = s (U - U_level) that the level flight's ``sinking_per_speed``
s gives:

    U = U_level - (e + integral of e / T_i) / (s T)

which makes e'' + e' / T + e / (T T_i) = 0 of a constant speed error: critically damped for
T_i = 4 T. T = 20 s leaves the depth's own transient (seconds: the MPC pitches the vehicle
within its horizon) to the MPC and moves the speed by 0.06 m/s for a 0.1 m error at 5 deg
(s = 0.079). The correction is held within a share of the level speed, and the integral
stops growing while it is held there (no wind-up).
"""

from __future__ import annotations

from auvmpc.models.level_flight import LevelFlight

__all__ = ["DepthHoldingPace"]

# The PI's time constant T (s) and integral time T_i = 4 T (critically damped, above).
TIME_CONSTANT_S = 20.0
INTEGRAL_TIME_S = 4.0 * TIME_CONSTANT_S
# The largest correction, as a share of the level flight's speed.
MOST_CORRECTION = 0.3
# Below this |s| (m/s of depth rate per m/s of speed) the depth does not answer the speed:
# no correction (a vehicle whose level flight is not a trim of one speed).
_LEAST_SINKING = 1e-3


class DepthHoldingPace:
    """The pace of one run's crippled vehicle (module docstring), sampled every
    ``sample_time`` s."""

    def __init__(self, sample_time: float) -> None:
        self.sample_time = sample_time
        self._integral = 0.0  # of the depth error (m s)

    def speed(self, flight: LevelFlight, depth_error: float) -> float:
        """The speed through the water (m/s) to fly at now, the depth ``depth_error`` (m,
        down positive) off its reference."""
        sinking = flight.sinking_per_speed
        if abs(sinking) < _LEAST_SINKING:
            return flight.speed
        integral = self._integral + depth_error * self.sample_time
        correction = -(depth_error + integral / INTEGRAL_TIME_S) / (sinking * TIME_CONSTANT_S)
        most = MOST_CORRECTION * flight.speed
        if abs(correction) <= most:
            self._integral = integral
        return flight.speed + max(-most, min(most, correction))
