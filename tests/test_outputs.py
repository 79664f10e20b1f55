"""Writing never destroys what auvmpc did not write (issue 12, item 1): the folder rule of
auvmpc.experiments.outputs, through the library and through every command that writes."""

from __future__ import annotations

import json
import os
import stat
import subprocess
import sys

import pytest

from auvmpc.errors import ConfigError
from auvmpc.experiments.outputs import (
    MARKER,
    OutputKind,
    atomic_write_text,
    check_output_folder,
    clean_stale_partials,
    own_kind,
    staged_folder,
)
from tests.test_cli import run_cli

SHORT = ("--set", "duration=2", "--no-figures")


def _user_folder(tmp_path):
    """A thesis folder: a user's file and a subfolder holding an auvmpc run folder."""
    folder = tmp_path / "thesis"
    (folder / "chapter").mkdir(parents=True)
    (folder / "thesis.tex").write_text("\\documentclass{article}\n")
    return folder


def _snapshot(folder):
    return {
        str(path.relative_to(folder)): path.read_bytes() if path.is_file() else None
        for path in sorted(folder.rglob("*"))
    }


@pytest.mark.parametrize(
    "command",
    [
        ("run", "paper-ideal", *SHORT, "--out"),
        ("reproduce", "--no-sweep", "--no-figures", "--out"),
        ("campaign", "paper-robustness", "--runs", "1", "--workers", "1", "--out"),
        ("plot",),
    ],
    ids=["run", "reproduce", "campaign", "plot"],
)
def test_a_users_folder_is_refused_and_untouched(monkeypatch, capsys, tmp_path, command):
    folder = _user_folder(tmp_path)
    before = _snapshot(folder)
    code, _, stderr = run_cli(monkeypatch, capsys, *command, str(folder))
    assert code == 2
    assert len(stderr.strip().splitlines()) == 1, stderr
    assert "auvmpc did not write" in stderr or "not a run folder" in stderr
    assert _snapshot(folder) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["thesis"]  # no staging left


@pytest.mark.parametrize("command", ["run", "reproduce", "campaign"])
def test_an_existing_file_is_refused_and_untouched(monkeypatch, capsys, tmp_path, command):
    target = tmp_path / "results"
    target.write_text("keep me")
    args = {
        "run": ("run", "paper-ideal", *SHORT),
        "reproduce": ("reproduce", "--no-sweep"),
        "campaign": ("campaign", "paper-robustness", "--runs", "1"),
    }[command]
    code, _, stderr = run_cli(monkeypatch, capsys, *args, "--out", str(target))
    assert code == 2 and "is a file" in stderr
    assert target.read_text() == "keep me"


def test_out_dot_is_a_folder_like_any_other(monkeypatch, capsys, tmp_path):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "notes.txt").write_text("mine")
    code, _, stderr = run_cli(monkeypatch, capsys, "run", "paper-ideal", *SHORT, "--out", ".")
    assert code == 2 and "--out: holds files auvmpc did not write" in stderr
    (tmp_path / "notes.txt").unlink()
    code, _, _ = run_cli(monkeypatch, capsys, "run", "paper-ideal", *SHORT, "--out", ".")
    assert code == 0 and (tmp_path / "run.json").is_file()


def test_a_run_folder_is_replaced_only_with_overwrite(monkeypatch, capsys, tmp_path):
    out = tmp_path / "run"
    assert run_cli(monkeypatch, capsys, "run", "paper-ideal", *SHORT, "--out", str(out))[0] == 0
    first = (out / "run.json").read_text()
    code, _, stderr = run_cli(monkeypatch, capsys, "run", "paper-ideal", *SHORT, "--out", str(out))
    assert code == 2 and "add --overwrite" in stderr
    assert (out / "run.json").read_text() == first
    args = ("run", "paper-ideal", "--set", "duration=3", "--no-figures", "--out", str(out))
    assert run_cli(monkeypatch, capsys, *args, "--overwrite")[0] == 0
    assert json.loads((out / "run.json").read_text())["scenario"]["duration"] == 3.0
    # ... but not when the user has put a file of their own into it
    (out / "notes.md").write_text("mine")
    code, _, stderr = run_cli(monkeypatch, capsys, *args, "--overwrite")
    assert code == 2 and "notes.md" in stderr and (out / "notes.md").read_text() == "mine"


def test_an_empty_folder_is_written(monkeypatch, capsys, tmp_path):
    out = tmp_path / "empty"
    out.mkdir()
    assert run_cli(monkeypatch, capsys, "run", "paper-ideal", *SHORT, "--out", str(out))[0] == 0
    assert own_kind(out) is OutputKind.RUN


def test_kinds_are_not_mixed(tmp_path):
    with staged_folder(tmp_path / "r", OutputKind.RUN, overwrite=False) as staging:
        (staging / "run.json").write_text("{}")
    with pytest.raises(ConfigError, match=r"--out: is an auvmpc run folder, not a campaign"):
        check_output_folder(tmp_path / "r", OutputKind.CAMPAIGN, overwrite=True, resume=True)


def test_the_root_and_a_path_through_a_file_are_refused(tmp_path):
    with pytest.raises(ConfigError, match="filesystem root"):
        check_output_folder("/", OutputKind.RUN, overwrite=True)
    (tmp_path / "file").write_text("x")
    with pytest.raises(ConfigError, match="is a file, not a folder"):
        check_output_folder(tmp_path / "file" / "run", OutputKind.RUN, overwrite=False)


def test_a_failed_write_leaves_nothing(tmp_path):
    with pytest.raises(RuntimeError, match="boom"):
        with staged_folder(tmp_path / "r", OutputKind.RUN, overwrite=False) as staging:
            (staging / "log.csv").write_text("t\n")
            raise RuntimeError("boom")
    assert list(tmp_path.iterdir()) == []


def test_stale_partials_of_auvmpc_are_cleaned_and_nothing_else(tmp_path):
    dead = _dead_pid()
    ours = tmp_path / f".r.{dead}.0123abcd.partial"
    ours.mkdir()
    (ours / MARKER).write_text(json.dumps({"kind": "run"}))
    (ours / "log.csv").write_text("t\n")
    empty = tmp_path / f".r.{dead}.89abcdef.partial"
    empty.mkdir()
    foreign = tmp_path / f".r.{dead}.00000000.partial"
    foreign.mkdir()
    (foreign / "data.bin").write_text("not ours")
    alive = tmp_path / f".r.{os.getpid()}.11111111.partial"
    alive.mkdir()
    (alive / MARKER).write_text(json.dumps({"kind": "run"}))
    other_name = tmp_path / f".s.{dead}.22222222.partial"
    other_name.mkdir()
    (other_name / MARKER).write_text(json.dumps({"kind": "run"}))
    assert sorted(clean_stale_partials(tmp_path, "r")) == sorted([ours, empty])
    assert foreign.exists() and alive.exists() and other_name.exists()


def test_a_killed_run_leaves_a_partial_that_the_next_run_cleans(monkeypatch, capsys, tmp_path):
    """SIGKILL while writing: simulated by a staging folder of a process that is gone."""
    stale = tmp_path / f".run.{_dead_pid()}.0123abcd.partial"
    stale.mkdir()
    (stale / MARKER).write_text(json.dumps({"kind": "run", "pid": 1}))
    (stale / "log.csv").write_text("t\n")
    code, _, _ = run_cli(
        monkeypatch, capsys, "run", "paper-ideal", *SHORT, "--out", str(tmp_path / "run")
    )
    assert code == 0 and not stale.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]


def test_files_get_the_users_permissions(tmp_path):
    old = os.umask(0o022)
    try:
        atomic_write_text(tmp_path / "a.md", "x")
        assert stat.S_IMODE((tmp_path / "a.md").stat().st_mode) == 0o644
        os.umask(0o077)
        atomic_write_text(tmp_path / "b.md", "x")
        assert stat.S_IMODE((tmp_path / "b.md").stat().st_mode) == 0o600
    finally:
        os.umask(old)


def test_bench_json_is_not_written_over_a_file(monkeypatch, capsys, tmp_path):
    target = tmp_path / "rows.json"
    target.write_text("mine")
    code, _, stderr = run_cli(monkeypatch, capsys, "bench", "--json", str(target))
    assert code == 2 and "--json: exists; add --overwrite" in stderr
    assert target.read_text() == "mine"


def _dead_pid() -> int:
    """The pid of a process that has exited (and been reaped)."""
    process = subprocess.Popen([sys.executable, "-c", "pass"])
    process.wait()
    return process.pid


def test_figures_redrawn_later_count_as_auvmpcs(monkeypatch, capsys, tmp_path):
    out = tmp_path / "run"
    assert run_cli(monkeypatch, capsys, "run", "paper-ideal", *SHORT, "--out", str(out))[0] == 0
    assert run_cli(monkeypatch, capsys, "plot", str(out))[0] == 0
    assert (out / "trajectory.png").is_file()
    code, _, stderr = run_cli(
        monkeypatch, capsys, "run", "paper-ideal", *SHORT, "--out", str(out), "--overwrite"
    )
    assert code == 0, stderr
