"""The README's "Using it" commands run in order in an empty folder (issue 30, item 4).

Each command goes through ``auvmpc.cli.main``, the function the console script calls, in
this process (run as separate processes, the import alone would add about 2 s to each of
the 21 commands). Lines are read from the section's first ``sh`` block: a trailing
backslash joins the next line, ``#`` starts a comment, ``cat > FILE <<'EOF'`` writes the
lines up to ``EOF`` to FILE, and ``. .venv/bin/activate`` is the shell's business. Every
other line must be an ``auvmpc`` command.

Left out, by one rule: the commands that take minutes and that the rest of the suite
covers on smaller inputs (``reproduce``, ``bench``, ``campaign``, ``campaign-report``,
``identify``, ``run --from-campaign``), ``export-c --blasfeo DIR`` and ``--aarch64 DIR``,
whose DIR the reader fetches first (``make blasfeo``, ``make hpipm-aarch64``), ``verify-c
--target`` of such an export, and the lines that take 5-11 s each
and that another test runs exactly (``animate``: tests/test_animation.py;
``run bluerov2-helix`` and ``run paper-6dof``: tests/test_six_dof_loop.py). ``export-c``
and ``verify-c`` are left out where there is no C compiler, make or HPIPM (as in
tests/test_export_c.py). About 18 s on a 2-core Xeon.
"""

from __future__ import annotations

import json
import shlex
import shutil
from pathlib import Path

import pytest

from auvmpc.native import compiler
from auvmpc.solvers.compiled_qp_step import _casadi_hpipm
from tests.test_cli import run_cli

pytestmark = pytest.mark.slow

README = Path(__file__).resolve().parents[1] / "README.md"
LONG_COMMANDS = {"reproduce", "bench", "campaign", "campaign-report", "identify", "animate"}
# --blasfeo, --generic-blasfeo and --aarch64 name folders the reader makes first (make
# blasfeo, make blasfeo-avx, make hpipm-aarch64); --target aarch64 needs the export made with
# --aarch64 (tests/test_export_c.py)
LONG_OPTIONS = {"--from-campaign", "--blasfeo", "--generic-blasfeo", "--aarch64", "--target"}
# Scenarios tests/test_six_dof_loop.py runs exactly (test_bluerov2_helix,
# test_paper_6dof_within_twice_the_planar_error_with_depth_and_attitude_bounded).
RUN_ELSEWHERE = {"bluerov2-helix", "paper-6dof"}
NEEDS_C = {"export-c", "verify-c"}
FIRST_RUN = ["run", "paper-obstacles", "--out"]


def using_it_lines() -> list[str]:
    """The "Using it" block's lines, continuation lines joined."""
    section = README.read_text().split("\n## Using it\n", 1)[1].split("\n## ", 1)[0]
    block = section.split("```sh\n", 1)[1].split("```", 1)[0]
    return block.replace("\\\n", " ").splitlines()


def steps(lines: list[str]):
    """``("file", path, text)`` for a here-document, ``("auvmpc", args)`` for a command;
    shell set-up lines and comment-only lines yield nothing."""
    lines = iter(lines)
    for line in lines:
        words = shlex.split(line, comments=True)
        if not words or words[0] == ".":
            continue
        if words[:2] == ["cat", ">"] and words[3] == "<<EOF":
            text = "".join(f"{body}\n" for body in iter(lines.__next__, "EOF"))
            yield "file", words[2], text
            continue
        while "=" in words[0]:  # NAME=value before the command
            words = words[1:]
        assert words[0] == "auvmpc", f"not an auvmpc command: {line!r}"
        yield "auvmpc", words[1:]


def left_out(args: list[str], have_cc: bool) -> bool:
    return (
        args[0] in LONG_COMMANDS
        or bool(LONG_OPTIONS & set(args))
        or (args[0] == "run" and bool(RUN_ELSEWHERE & set(args)))
        or (args[0] in NEEDS_C and not have_cc)
    )


def test_the_using_it_block_runs_top_to_bottom_in_an_empty_folder(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    have_cc = bool(compiler() and shutil.which("make") and _casadi_hpipm())
    ran, first_run = [], None
    for step in steps(using_it_lines()):
        if step[0] == "file":
            _, path, text = step
            Path(path).write_text(text)
            continue
        args = step[1]
        if left_out(args, have_cc):
            continue
        code, _, err = run_cli(monkeypatch, capsys, *args)
        assert code == 0, f"auvmpc {shlex.join(args)} exited {code}: {err.strip()}"
        ran.append(args[0])
        if args[:3] == FIRST_RUN and first_run is None:
            first_run = Path(args[3])
    assert len(ran) >= 15 and {"explain", "compare", "export"} <= set(ran)
    assert first_run is not None, "the block has no `auvmpc run paper-obstacles --out DIR`"
    metrics = json.loads((first_run / "run.json").read_text())["metrics"]
    assert metrics["verdict"] == "ok", metrics["verdict_reason"]
