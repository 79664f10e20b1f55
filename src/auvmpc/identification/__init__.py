"""Identification of a vehicle's 3-DOF model from logs (docs/identification.md).

- :mod:`~auvmpc.identification.excitation`: the manoeuvre (``auvmpc excite``)
- :mod:`~auvmpc.identification.logs`: what a log gives (velocities, thrusts or body force),
  run folders, resampling; :mod:`~auvmpc.identification.rosbag` (ROS 2 bags),
  :mod:`~auvmpc.identification.dataflash` (ArduSub DataFlash logs),
  :mod:`~auvmpc.identification.thruster_curve` (PWM to force)
- :mod:`~auvmpc.identification.estimation`: equation error, output error, intervals (a
  current and a thrust gain as optional unknowns)
- :mod:`~auvmpc.identification.report`: vehicle file, identification.json, report, figure
"""

from auvmpc.identification.estimation import PARAMETERS, Identification, Unknowns, identify
from auvmpc.identification.excitation import design_excitation, write_excitation
from auvmpc.identification.logs import LogOptions, VelocityLog, read_log, read_run_folder
from auvmpc.identification.report import write_identification

__all__ = [
    "PARAMETERS",
    "Identification",
    "LogOptions",
    "Unknowns",
    "VelocityLog",
    "design_excitation",
    "identify",
    "read_log",
    "read_run_folder",
    "write_excitation",
    "write_identification",
]
