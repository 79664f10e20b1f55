"""Scenarios: the typed schema (:mod:`.model`), what a scenario resolves to for its vehicle
(:mod:`.resolved`), the loader with overrides (:mod:`.loader`), the checks before a run
(:mod:`.sanity`)."""

from auvmpc.controllers.config import ControllerConfig, ControllerType
from auvmpc.scenario.loader import (
    apply_override,
    builtin_scenarios,
    load_scenario,
    planar_twin,
    scenario_to_dict,
    validate_document,
    validate_scenario,
)
from auvmpc.scenario.model import (
    DEFAULT_PLANT_STEP_S,
    PlantConfig,
    Scenario,
    SixDofDisturbanceConfig,
    SixDofScenario,
    SixDofSensingConfig,
    check_one_sample_time,
    whole_samples,
)
from auvmpc.scenario.resolved import (
    ResolvedDepthScenario,
    ResolvedScenario,
    ResolvedSixDofScenario,
)

__all__ = [
    "DEFAULT_PLANT_STEP_S",
    "ControllerConfig",
    "ControllerType",
    "PlantConfig",
    "ResolvedDepthScenario",
    "ResolvedScenario",
    "ResolvedSixDofScenario",
    "Scenario",
    "SixDofDisturbanceConfig",
    "SixDofScenario",
    "SixDofSensingConfig",
    "apply_override",
    "builtin_scenarios",
    "check_one_sample_time",
    "whole_samples",
    "load_scenario",
    "planar_twin",
    "scenario_to_dict",
    "validate_document",
    "validate_scenario",
]
