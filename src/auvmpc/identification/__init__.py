"""Identification of a vehicle's 3-DOF, heave and roll and pitch models from logs
(docs/identification.md).

- :mod:`~auvmpc.identification.excitation`: the manoeuvre (``auvmpc excite``), horizontal,
  heave or 6-DOF
- :mod:`~auvmpc.identification.logs`: what a log gives (velocities, thrusts or body force),
  run folders, resampling; :mod:`~auvmpc.identification.rosbag` (ROS 2 bags),
  :mod:`~auvmpc.identification.dataflash` (ArduSub DataFlash logs),
  :mod:`~auvmpc.identification.thruster_curve` (PWM to force)
- :mod:`~auvmpc.identification.estimation`: equation error, output error, intervals, over
  a grey-box model (the 3-DOF one with a current and a thrust gain as optional unknowns);
  :mod:`~auvmpc.identification.heave`: the heave model's, its logs;
  :mod:`~auvmpc.identification.roll_pitch`: roll and pitch's;
  :mod:`~auvmpc.identification.six_dof_log`: all three from one 6-DOF log
- :mod:`~auvmpc.identification.report`: vehicle file, identification.json, report, figure
"""

from auvmpc.identification.estimation import (
    EXTRAS,
    PARAMETERS,
    GreyBox,
    HorizontalGreyBox,
    Identification,
    identify,
)
from auvmpc.identification.excitation import Dof, design_excitation, write_excitation
from auvmpc.identification.heave import HeaveGreyBox, read_heave_log
from auvmpc.identification.logs import LogOptions, VelocityLog, read_log, read_run_folder
from auvmpc.identification.report import write_identification

__all__ = [
    "EXTRAS",
    "PARAMETERS",
    "Dof",
    "GreyBox",
    "HeaveGreyBox",
    "HorizontalGreyBox",
    "Identification",
    "LogOptions",
    "VelocityLog",
    "design_excitation",
    "identify",
    "read_heave_log",
    "read_log",
    "read_run_folder",
    "write_excitation",
    "write_identification",
]
