"""Damaged run folders and campaign stores (issue 28, item 3): every command that reads one
says in one line which file is damaged and how, exit 2, never a traceback; verify-c refuses
a log that is not whole. The damaged copies are made from one short real run (and one small
campaign) per module; every command runs in-process."""

from __future__ import annotations

import json
import shutil
import sqlite3

import numpy as np
import pytest

from auvmpc.experiments.campaign import RESULTS_FILE, run_campaign
from tests.conftest import run_and_export
from tests.test_campaign import write_campaign
from tests.test_cli import run_cli

# One short run: 10 s of the paper's ideal scenario (21 samples), without figures.
_SHORT = ["duration=10"]


def _lines(text: str) -> list[str]:
    return [line for line in text.splitlines() if line.strip()]


def _cut_mid_row(folder):
    text = (folder / "log.csv").read_text()
    (folder / "log.csv").write_text(text[: len(text) // 2])


def _cut_at_row(folder):
    lines = (folder / "log.csv").read_text().splitlines(keepends=True)
    (folder / "log.csv").write_text("".join(lines[: len(lines) // 2]))


def _edit_log(row: int, column: str, value: str):
    """Row ``row`` (0: the first sample) of ``column`` set to ``value``."""

    def damage(folder):
        lines = (folder / "log.csv").read_text().splitlines()
        header = lines[0].split(",")
        cells = lines[row + 1].split(",")
        cells[header.index(column)] = value
        lines[row + 1] = ",".join(cells)
        (folder / "log.csv").write_text("\n".join(lines) + "\n")

    return damage


def _drop_column(name: str):
    def damage(folder):
        lines = [line.split(",") for line in (folder / "log.csv").read_text().splitlines()]
        i = lines[0].index(name)
        (folder / "log.csv").write_text("".join(",".join(r[:i] + r[i + 1 :]) + "\n" for r in lines))

    return damage


def _extra_rows(folder):
    """The log of a longer run under this run's run.json: rows past its duration."""
    lines = (folder / "log.csv").read_text().splitlines()
    body = lines[1:-1]
    step = float(body[1].split(",")[0]) - float(body[0].split(",")[0])
    end = float(lines[-1].split(",")[0])
    more = []
    for k, line in enumerate(body, start=1):
        cells = line.split(",")
        cells[0] = repr(end + k * step - step)
        more.append(",".join(cells))
    final = lines[-1].split(",")
    final[0] = repr(end + len(body) * step)
    text = "\n".join([lines[0], *body, *more, ",".join(final)]) + "\n"
    (folder / "log.csv").write_text(text)


def _write(name: str, data: bytes | str):
    def damage(folder):
        raw = data.encode() if isinstance(data, str) else data
        (folder / name).write_bytes(raw)

    return damage


def _header_only(folder):
    header = (folder / "log.csv").read_text().splitlines()[0]
    (folder / "log.csv").write_text(header + "\n")


def _run_json(change):
    def damage(folder):
        info = json.loads((folder / "run.json").read_text())
        (folder / "run.json").write_text(json.dumps(change(info)))

    return damage


def _without(key: str):
    return _run_json(lambda info: {k: v for k, v in info.items() if k != key})


def _bad_duration(info):
    info["scenario"]["duration"] = "long"
    return info


# damage kind -> (how, the file the line names, what it says)
DAMAGE = {
    "log cut mid-row": (_cut_mid_row, "log.csv", "cut short"),
    "log cut at a row boundary": (_cut_at_row, "log.csv", "cut short"),
    "log header only": (_header_only, "log.csv", "0 rows after its header"),
    "log empty": (_write("log.csv", b""), "log.csv", "is empty"),
    "log binary": (_write("log.csv", bytes(range(256)) * 8), "log.csv", "binary"),
    "log not UTF-8": (_write("log.csv", b"t,x\n0.0,caf\xe9\n"), "log.csv", "UTF-8"),
    "log not a log": (_write("log.csv", "a,b\n1,2\n"), "log.csv", "no column t"),
    "log column missing": (_drop_column("psi"), "log.csv", "no column psi"),
    "log NaN state": (_edit_log(5, "x", "nan"), "log.csv", "line 7, column x"),
    "log not a number": (_edit_log(3, "u", "fast"), "log.csv", "'fast' is not a number"),
    "log time not increasing": (_edit_log(4, "t", "0.5"), "log.csv", "is not after"),
    "log longer than run.json": (_extra_rows, "log.csv", "more than 20"),
    "run.json empty": (_write("run.json", b""), "run.json", "not valid JSON"),
    "run.json a list": (_write("run.json", "[1, 2]"), "run.json", "holds a list"),
    "run.json binary": (_write("run.json", bytes(range(256))), "run.json", "binary"),
    "run.json no model": (_without("model"), "run.json", "no 'model'"),
    "run.json no scenario": (_without("scenario"), "run.json", "no 'scenario'"),
    "run.json bad scenario": (_run_json(_bad_duration), "run.json", "scenario.duration"),
}


@pytest.fixture(scope="module")
def made(tmp_path_factory):
    """One healthy run folder and an export-c folder of its scenario."""
    return run_and_export(tmp_path_factory.mktemp("damaged"), _SHORT)


def _command(name: str, folder, made) -> list[str]:
    return {
        "plot": ["plot", str(folder)],
        "animate": ["animate", str(folder), "--out", str(folder.parent / "a.gif")],
        "compare": ["compare", str(made / "healthy"), str(folder), "--out", str(folder) + "-c"],
        "export": ["export", str(folder)],
        "verify-c": ["verify-c", str(made / "export"), str(folder)],
    }[name]


# Not damage to that command: a horizontal run's bag needs no model.
_READS_NO_MODEL = {("run.json no model", "export")}


@pytest.mark.parametrize(
    ("kind", "command"),
    [
        (kind, command)
        for kind in DAMAGE
        for command in ("plot", "animate", "compare", "export", "verify-c")
        if (kind, command) not in _READS_NO_MODEL
    ],
)
def test_a_damaged_run_folder_is_one_line_naming_the_file(
    made, tmp_path, monkeypatch, capsys, kind, command
):
    damage, file, says = DAMAGE[kind]
    folder = tmp_path / "run"
    shutil.copytree(made / "healthy", folder)
    damage(folder)
    before = {p.name: p.read_bytes() for p in folder.iterdir()}
    code, _, err = run_cli(monkeypatch, capsys, *_command(command, folder, made))
    assert code == 2, err
    assert "Traceback" not in err
    lines = _lines(err)
    assert 1 <= len(lines) <= 3, err
    assert file in lines[0] and says in lines[0], lines[0]
    assert {p.name: p.read_bytes() for p in folder.iterdir()} == before  # nothing touched


def test_plot_names_a_damaged_marker(made, tmp_path, monkeypatch, capsys):
    folder = tmp_path / "run"
    shutil.copytree(made / "healthy", folder)
    (folder / ".auvmpc-output.json").write_text('{"kind": "run", "files": [')
    code, _, err = run_cli(monkeypatch, capsys, "plot", str(folder))
    assert code == 2 and "Traceback" not in err and len(_lines(err)) == 1, err
    assert ".auvmpc-output.json is damaged" in err


def test_verify_c_refuses_a_damaged_export_json_in_one_line(made, tmp_path, monkeypatch, capsys):
    export = tmp_path / "export"
    shutil.copytree(made / "export", export)
    for text, says in (("{", "not valid JSON"), ("[]", "holds a list"), ('{"model": 1}', "")):
        (export / "export.json").write_text(text)
        code, _, err = run_cli(monkeypatch, capsys, "verify-c", str(export), str(made / "healthy"))
        assert code == 2 and "Traceback" not in err and len(_lines(err)) == 1, err
        assert "export.json" in err and says in err


def test_identify_reads_log_csv_with_the_same_checks(tmp_path, monkeypatch, capsys):
    """identify's reader is the log's table reader: a row cut short and a NaN are one line
    naming the file and the line."""
    rows = ["t,u,v,r,F1,F2,F3,F4"]
    rows += [f"{0.1 * k:.1f},0.1,0.0,0.0,{np.sin(0.1 * k):.4f},1.0,1.0,1.0" for k in range(200)]
    cases = {
        "cut": ("\n".join(rows)[:-7], "ends in the middle of line 201"),
        "nan": ("\n".join(rows).replace("0.1,0.0,0.0", "nan,0.0,0.0", 1) + "\n", "line 2"),
    }
    for name, (text, says) in cases.items():
        (tmp_path / name).mkdir()
        (tmp_path / name / "log.csv").write_text(text)
        out = str(tmp_path / f"{name}.yaml")
        args = ("identify", str(tmp_path / name), "--vehicle", "jmse2210", "--out", out)
        code, _, err = run_cli(monkeypatch, capsys, *args)
        assert code == 2 and "Traceback" not in err and len(_lines(err)) == 1, err
        assert "log.csv" in err and says in err


# --- campaign stores ---------------------------------------------------------------------


@pytest.fixture(scope="module")
def campaign_folder(tmp_path_factory):
    """A finished two-run campaign of 10 s runs."""
    base = tmp_path_factory.mktemp("campaign")
    spec = {
        "name": "tiny",
        "description": "two short runs",
        "base": "paper-ideal",
        "overrides": _SHORT,
        "runs": 2,
        "seed": 1,
        "parameters": {
            "initial_state.0": {"type": "uniform", "low": -0.5, "high": 0.5, "apply": "add"}
        },
    }
    run_campaign(write_campaign(base, spec), base / "c", workers=1)
    return base / "c"


def _truncate(path):
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])


def _drop_runs(path):
    with sqlite3.connect(path) as db:
        db.execute("DROP VIEW results")
        db.execute("DROP TABLE runs")
    db.close()


STORE_DAMAGE = {
    "truncated": (_truncate, "malformed"),
    "garbage": (lambda path: path.write_bytes(bytes(range(256)) * 32), "not a database"),
    "empty": (lambda path: path.write_bytes(b""), "no such table: campaign"),
    "a table missing": (_drop_runs, "no such table: runs"),
}


# Not damage to that command: a rerun reads only the campaign's own row, which is there; a
# campaign killed before its first write leaves an empty file, which it resumes.
_NOT_DAMAGE = {("a table missing", "run --from-campaign"), ("empty", "campaign")}


@pytest.mark.parametrize(
    ("kind", "command"),
    [
        (kind, command)
        for kind in STORE_DAMAGE
        for command in ("campaign-report", "run --from-campaign", "campaign")
        if (kind, command) not in _NOT_DAMAGE
    ],
)
def test_a_damaged_campaign_store_is_one_line_naming_it(
    campaign_folder, tmp_path, monkeypatch, capsys, kind, command
):
    damage, says = STORE_DAMAGE[kind]
    folder = tmp_path / "c"
    shutil.copytree(campaign_folder, folder)
    for companion in folder.glob(f"{RESULTS_FILE}-*"):  # the write-ahead log, checkpointed
        companion.unlink()
    damage(folder / RESULTS_FILE)
    file = str(campaign_folder.parent / "campaign.yaml")
    args = {
        "campaign-report": ["campaign-report", str(folder), "--no-figures"],
        "run --from-campaign": [
            "run", "--from-campaign", str(folder), "--index", "0", "--out", str(tmp_path / "r")
        ],
        "campaign": ["campaign", file, "--out", str(folder)],
    }[command]  # fmt: skip
    before = (folder / RESULTS_FILE).read_bytes()
    code, _, err = run_cli(monkeypatch, capsys, *args)
    assert code == 2, err
    assert "Traceback" not in err
    assert len(_lines(err)) == 1, err
    assert RESULTS_FILE in err and says in err, err
    assert (folder / RESULTS_FILE).read_bytes() == before
