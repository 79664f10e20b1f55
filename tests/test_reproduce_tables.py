"""The reproduction's tables explain themselves (issue 30): every column of summary.md,
depth.md and six_dof.md has a legend entry, and every summary row that misses one of the
paper's claims links to a heading of docs/paper-reproduction.md that explains it. Built from
hand-made rows, no simulation."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from auvmpc.experiments.paper_claims import PAPER_CLAIMS, PAPER_REPRODUCTION_DOC
from auvmpc.experiments.reproduce import (
    DEPTH_COLUMNS,
    SIX_DOF_COLUMNS,
    SUMMARY_COLUMNS,
    depth_markdown,
    six_dof_markdown,
    summary_markdown,
    sweep_scale,
)
from auvmpc.scenario import load_scenario

ROOT = Path(__file__).resolve().parents[1]
LINK = re.compile(r"\]\(([^)#]*)#([^)]*)\)")
TRANSIENTS = {"paper-ideal": 20.0, "paper-disturbed": 30.0, "paper-obstacles": 20.0}


def _anchors(markdown: str) -> set[str]:
    """GitHub's (and mkdocs') anchors of the headings: lower case, punctuation dropped,
    spaces to hyphens."""
    headings = re.findall(r"^#+ (.+)$", markdown, flags=re.MULTILINE)
    return {re.sub(r"[^\w\- ]", "", heading).lower().replace(" ", "-") for heading in headings}


DOC_ANCHORS = _anchors((ROOT / PAPER_REPRODUCTION_DOC).read_text())


def _tables(markdown: str) -> list[list[list[str]]]:
    """Each markdown table as rows of cells, the separator line left out."""
    tables, current = [], []
    for line in [*markdown.splitlines(), ""]:
        if line.startswith("|"):
            if not line.startswith("|---"):
                current.append([cell.strip() for cell in line.strip("|").split(" | ")])
        elif current:
            tables.append(current)
            current = []
    return tables


def _summary_row(scenario: str, controller: str, **metrics) -> dict:
    """A row that meets every claim unless ``metrics`` say otherwise."""
    row = {
        "scenario": scenario, "controller": controller, "level": None,
        "rms_position_error_m": 0.05, "max_position_error_m": 0.5,
        "final_position_error_m": 1e-5, "rms_position_error_after_transient_m": 0.004,
        "max_position_error_after_transient_m": 0.006,
        "min_obstacle_clearance_m": 0.1 if scenario == "paper-obstacles" else None,
        "thrust_limit_violations": 0, "thrust_rate_violations": 0, "solver_failures": 0,
        "solve_ms_median": 1.0, "solve_ms_p99": 2.0, "solve_ms_max": 3.0,
        "settle_u_s": 5.0, "settle_v_s": 7.0, "settle_r_s": 4.5,
    }  # fmt: skip
    return row | metrics


SUMMARY_ROWS = [
    # misses both of paper-ideal's claims
    _summary_row("paper-ideal", "mpc", rms_position_error_after_transient_m=0.24, settle_r_s=None),
    _summary_row("paper-ideal", "ltv-mpc-nc30"),
    _summary_row("paper-disturbed", "mpc", max_position_error_after_transient_m=38.6),
    _summary_row(
        "paper-disturbed", "ltv-mpc", level=-1.0, max_position_error_after_transient_m=3.7
    ),
    _summary_row("paper-obstacles", "baseline", min_obstacle_clearance_m=-1.25),
    _summary_row("paper-obstacles", "mpc"),
]
DEPTH_ROW = {
    "scenario": "paper-depth-waves", "rise_time_s": 1.6, "settling_time_0p05m_s": 1.7,
    "settling_time_2pct_s": None, "overshoot_m": 0.0087, "steady_state_error_mean_abs_m": 0.0045,
    "steady_state_error_max_abs_m": 0.0087, "max_z_m": -0.25, "thrust_limit_violations": 0,
    "thrust_rate_violations": 0, "solve_ms_median": 4.8,
}  # fmt: skip
SIX_DOF_ROW = {column.key: 0.1 for column in SIX_DOF_COLUMNS} | {
    "scenario": "paper-6dof", "controller": "mpc", "plant": "3-DOF",
    "depth_rms_error_after_transient_m": None, "verdict": "ok",
}  # fmt: skip


@pytest.mark.parametrize(
    ("markdown", "columns"),
    [
        (summary_markdown(SUMMARY_ROWS, TRANSIENTS), SUMMARY_COLUMNS),
        (depth_markdown([DEPTH_ROW]), DEPTH_COLUMNS),
        (six_dof_markdown([SIX_DOF_ROW]), SIX_DOF_COLUMNS),
    ],
    ids=["summary", "depth", "six_dof"],
)
def test_every_column_has_a_legend_entry(markdown, columns):
    results, legend = _tables(markdown)[:2]
    headers = results[0]
    assert len(headers) == len(columns)
    assert all(len(row) == len(headers) for row in results)
    assert legend[0][:1] == ["column"]
    assert [entry[0] for entry in legend[1:]] == headers
    assert all(entry[-1] for entry in legend[1:])  # each has a meaning


def test_each_row_that_misses_a_claim_links_to_its_explanation():
    results = _tables(summary_markdown(SUMMARY_ROWS, TRANSIENTS))[0]
    claim = results[0].index("paper's claim")
    cells = {(row[0], row[1]): row[claim] for row in results[1:]}
    assert cells[("paper-ideal", "ltv-mpc-nc30")] == "met"
    assert cells[("paper-obstacles", "mpc")] == "met"
    missed = {key: LINK.findall(cell) for key, cell in cells.items() if cell.startswith("missed")}
    assert {key: len(links) for key, links in missed.items()} == {
        ("paper-ideal", "mpc"): 2,
        ("paper-disturbed", "mpc"): 1,
        ("paper-disturbed", "ltv-mpc"): 1,
        ("paper-obstacles", "baseline"): 1,
    }
    for links in missed.values():
        for path, anchor in links:
            assert path == PAPER_REPRODUCTION_DOC
            assert anchor in DOC_ANCHORS


def test_every_claim_is_explained_under_a_heading_of_the_doc():
    assert {claim.anchor for claim in PAPER_CLAIMS} <= DOC_ANCHORS


def test_the_uncertainty_column_says_paper_disturbed_is_the_sweeps_lowest_level():
    """The legend's `-` for paper-disturbed means level -1; the preset must stay so."""
    scale = load_scenario("paper-disturbed").scenario.plant.scale
    assert [f"plant.scale.{name}={value:.6g}" for name, value in scale.items()] == list(
        sweep_scale(-1.0)
    )
