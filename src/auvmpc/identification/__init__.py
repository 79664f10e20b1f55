"""Identification of a vehicle's 3-DOF model from logs (docs/identification.md).

- :mod:`~auvmpc.identification.excitation`: the manoeuvre (``auvmpc excite``)
- :mod:`~auvmpc.identification.logs`: what a log gives (velocities, thrusts), run folders
- :mod:`~auvmpc.identification.estimation`: equation error, output error, intervals
- :mod:`~auvmpc.identification.report`: vehicle file, identification.json, report, figure
"""

from auvmpc.identification.estimation import PARAMETERS, Identification, identify
from auvmpc.identification.excitation import design_excitation, write_excitation
from auvmpc.identification.logs import VelocityLog, read_run_folder
from auvmpc.identification.report import write_identification

__all__ = [
    "PARAMETERS",
    "Identification",
    "VelocityLog",
    "design_excitation",
    "identify",
    "read_run_folder",
    "write_excitation",
    "write_identification",
]
