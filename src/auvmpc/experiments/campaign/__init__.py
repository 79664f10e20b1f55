"""Robustness campaigns: one scenario run many times with sampled parameters.

A campaign file names a base scenario (or a kind of generated case), distributions over
any scenario field, a number of runs and one master seed (``docs/campaigns.md`` has the
full format). Run ``k``'s parameters and scenario seed are a pure function of
``(master seed, k)``, so any run can be reproduced alone (:func:`run_overrides`,
:func:`scenario_for_run`).

Runs execute on local processes (``concurrent.futures``, spawn start method) or on a Dask
distributed cluster. Only the coordinating process writes results: one SQLite
transaction per finished run in ``DIR/results.sqlite``, so a campaign killed at any moment
resumes with the same command, redoing nothing that finished and losing nothing.

Data flow::

    load_campaign(FILE) -> validate_campaign -> run_campaign(... DIR)
        -> execute_run(k) on a worker: plan_run -> load scenario -> runner.simulate
        -> one row per run in DIR/results.sqlite -> load_results(DIR) -> campaign_report

Modules: ``spec`` (campaign files), ``sampling`` (parameters of run k, validation),
``store`` (SQLite), ``execute`` (workers, local pool, Dask), ``paired`` (the yardstick twin
of every run and the report's paired section), ``report`` (results and report),
``criterion`` (success expressions).
"""

from __future__ import annotations

from auvmpc.experiments.campaign.criterion import (
    Criterion,
    parse_criterion,
    wilson_interval,
)
from auvmpc.experiments.campaign.execute import (
    CampaignSummary,
    execute_run,
    run_campaign,
)
from auvmpc.experiments.campaign.report import (
    CampaignReport,
    campaign_report,
    load_results,
    paired_difference,
)
from auvmpc.experiments.campaign.sampling import (
    RunSample,
    reproduce_command,
    run_overrides,
    sample_run,
    scenario_for_run,
    validate_campaign,
)
from auvmpc.experiments.campaign.spec import (
    MAX_WORKER_DEATHS,
    NONDETERMINISTIC_COLUMNS,
    RESULTS_FILE,
    TIMING_METRICS,
    ApplyMode,
    Campaign,
    CampaignSpec,
    builtin_campaigns,
    load_campaign,
)
from auvmpc.experiments.campaign.store import (
    count_finished,
    stored_campaign,
    stored_sessions,
)

__all__ = [
    "ApplyMode",
    "Campaign",
    "CampaignReport",
    "CampaignSpec",
    "CampaignSummary",
    "Criterion",
    "MAX_WORKER_DEATHS",
    "RESULTS_FILE",
    "NONDETERMINISTIC_COLUMNS",
    "RunSample",
    "TIMING_METRICS",
    "builtin_campaigns",
    "campaign_report",
    "count_finished",
    "execute_run",
    "load_campaign",
    "load_results",
    "paired_difference",
    "parse_criterion",
    "reproduce_command",
    "run_campaign",
    "run_overrides",
    "sample_run",
    "scenario_for_run",
    "stored_campaign",
    "stored_sessions",
    "validate_campaign",
    "wilson_interval",
]
