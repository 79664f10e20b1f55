"""Load a scenario, change it, simulate, and look at the result from Python.

python examples/quickstart.py [OUTPUT_FOLDER]
"""

import sys
from pathlib import Path

import auvmpc

out = Path(sys.argv[1] if len(sys.argv) > 1 else "example-output")

# A built-in scenario with two changes: a shorter run and a larger first obstacle.
# Any field of docs/scenario-reference.md can be set this way.
scenario = auvmpc.load_scenario(
    "paper-obstacles",
    {"duration": 30, "obstacles.0.radius": 1.2},
    controller="ltv-mpc-nc30",  # a bench label: ltv-mpc with every move of 30 free
)
print(scenario.scenario.controller.type, "on", scenario.model.name)

run = auvmpc.simulate(scenario)

# The log as a pandas DataFrame: the columns of log.csv, one row per 0.5 s sample.
log = auvmpc.log_dataframe(run)
log["position_error_m"] = ((log.x - log.x_ref) ** 2 + (log.y - log.y_ref) ** 2) ** 0.5
print(log[["t", "x", "y", "position_error_m", "F1"]].tail(3).to_string(index=False))

# The metrics of run.json.
for name in ("rms_position_error_m", "min_obstacle_clearance_m", "solve_ms_median"):
    print(f"{name:28} {run.metrics[name]:.3f}")

# Matplotlib figures (no pyplot needed): save one, or the whole run folder.
figures = auvmpc.figures(run)
out.mkdir(parents=True, exist_ok=True)
figures["trajectory"].savefig(out / "quickstart-trajectory.png", dpi=120)
auvmpc.save_run(run, out / "quickstart-run", figures=False)
print("wrote", out)
