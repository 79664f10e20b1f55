"""The same scenario and controller on two vehicles, overlaid, with a metrics table.

python examples/compare_vehicles.py [OUTPUT_FOLDER]
"""

import sys
from pathlib import Path

import pandas as pd

import auvmpc
from auvmpc.plots import figure_compare_errors, save_figures

out = Path(sys.argv[1] if len(sys.argv) > 1 else "example-output")

base = auvmpc.load_scenario("paper-disturbed", {"duration": 20})
runs = {}
for vehicle in ("jmse2210", "bluerov2-heavy"):
    scenario = auvmpc.override(base, {"vehicle": vehicle})
    runs[vehicle] = auvmpc.simulate(scenario)

table = pd.DataFrame({vehicle: run.metrics for vehicle, run in runs.items()}).loc[
    ["rms_position_error_m", "max_abs_thrust_N", "thrust_effort_N2s"]
]
print(table.to_string(float_format="{:.3f}".format))

figure = figure_compare_errors([(name, run.log) for name, run in runs.items()], "paper-disturbed")
print("wrote", *save_figures({"compare-vehicles-errors": figure}, out))
