"""Thrust from an ESC's PWM command: a thruster's published bollard curve.

A DataFlash log records what the autopilot sent each ESC (RCOU, PWM in us), not the force;
identification needs the force. A curve maps one to the other by linear interpolation in a
table measured by the maker. Presets (``presets/thrusters/t200.csv``, the numbers and their
source in its header): the Blue Robotics T200 at 12 V and 16 V, from Blue Robotics'
published T200-Public-Performance-Data-10-20V-September-2019.xlsx (Basic ESC R3, bollard,
zero inflow). A curve is static: no thruster dynamics, no inflow loss at speed (the
thrust a moving vehicle gets is smaller; identify's thruster gain is not identified yet).

``--thruster-curve`` takes a preset name or a CSV file of the same shape with the columns
``pwm_us`` and ``force_n`` (N).
"""

from __future__ import annotations

from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import numpy as np

from auvmpc.errors import ConfigError

__all__ = ["PRESETS", "STANDARD_GRAVITY", "ThrusterCurve", "thruster_curve"]

# N per kgf (the standard acceleration of gravity, ISO 80000-3).
STANDARD_GRAVITY = 9.80665
# preset -> column of presets/thrusters/t200.csv (kgf)
PRESETS = {"t200-12v": "kgf_12v", "t200-16v": "kgf_16v"}
# An output of 0 us is an ESC channel switched off (disarmed, or not a motor): no thrust.
OFF_PWM_US = 0.0


@dataclass(frozen=True)
class ThrusterCurve:
    name: str
    pwm_us: np.ndarray  # (m,) increasing
    force_n: np.ndarray  # (m,)

    def force(self, pwm_us: np.ndarray) -> np.ndarray:
        """N for each PWM (us); clamped to the table's ends, 0 for an output that is off."""
        pwm = np.asarray(pwm_us, dtype=float)
        force = np.interp(pwm, self.pwm_us, self.force_n)
        return np.where(pwm == OFF_PWM_US, 0.0, force)


def _table(text: str, source: str, columns: tuple[str, str], scale: float) -> ThrusterCurve:
    lines = [line for line in text.splitlines() if line.strip() and not line.startswith("#")]
    header = [name.strip() for name in lines[0].split(",")]
    missing = [name for name in columns if name not in header]
    if missing:
        raise ConfigError(
            "--thruster-curve", source, f"has no column {', '.join(missing)} (need pwm_us, force_n)"
        )
    try:
        rows = np.array([[float(cell) for cell in line.split(",")] for line in lines[1:]])
    except ValueError:
        raise ConfigError("--thruster-curve", source, "holds a cell that is not a number") from None
    if rows.ndim != 2 or len(rows) < 2:
        raise ConfigError("--thruster-curve", source, "needs at least two rows")
    pwm, force = (rows[:, header.index(name)] for name in columns)
    if np.any(np.diff(pwm) <= 0) or not np.all(np.isfinite(force)):
        raise ConfigError("--thruster-curve", source, "pwm_us must increase, forces be numbers")
    return ThrusterCurve(source, pwm, force * scale)


def thruster_curve(name: str) -> ThrusterCurve:
    """A preset (:data:`PRESETS`) or a CSV file with ``pwm_us, force_n``."""
    if name in PRESETS:
        text = resources.files("auvmpc.presets").joinpath("thrusters/t200.csv").read_text()
        return _table(text, name, ("pwm_us", PRESETS[name]), STANDARD_GRAVITY)
    path = Path(name)
    if not path.is_file():
        raise ConfigError(
            "--thruster-curve", name, f"neither a preset ({', '.join(PRESETS)}) nor a CSV file"
        )
    return _table(path.read_text(), name, ("pwm_us", "force_n"), 1.0)
