"""A user's file is never deleted, changed or written into, by any writer, with or without
--overwrite (issue 28, item 2); files auvmpc adds to its own folder later are its own
(issue 30, item 3). One short run serves the whole module; folders are copied from it."""

from __future__ import annotations

import errno
import json
import os
import shlex
import shutil
import sqlite3
import subprocess
import sys
from pathlib import Path

import pytest

from auvmpc.experiments.outputs import (
    MARKER,
    OutputKind,
    check_output_folder,
    mark_folder,
    staged_folder,
)
from tests.test_cli import run_cli

SHORT = ("--set", "duration=2", "--no-figures")
CAMPAIGN = ("campaign", "paper-robustness", "--runs", "1", "--workers", "1", "--out")


@pytest.fixture(scope="module")
def short_run(tmp_path_factory):
    """A 2 s run folder written by auvmpc (about 1 s)."""
    from auvmpc.experiments.run import simulate, write_run
    from auvmpc.scenario import load_scenario

    out = tmp_path_factory.mktemp("short") / "run"
    return write_run(simulate(load_scenario("paper-ideal", ["duration=2"])), out, figures=False)


@pytest.fixture
def run_folder(short_run, tmp_path):
    """A fresh copy of the module's run folder (a copy keeps the marker)."""
    return shutil.copytree(short_run, tmp_path / "run")


def _snapshot(folder):
    return {
        str(path.relative_to(folder)): path.read_bytes() if path.is_file() else None
        for path in sorted(folder.rglob("*"))
    }


def _refused(monkeypatch, capsys, *args, fragment: str) -> str:
    code, _, err = run_cli(monkeypatch, capsys, *args)
    assert code == 2, err
    # One error line; a pre-run warning may come before it (SHORT cuts the paper's path).
    lines = err.strip().splitlines()
    errors = [line for line in lines if not line.startswith("warning:")]
    assert len(errors) == 1 and len(lines) <= 3 and "Traceback" not in err, err
    assert fragment in err, err
    return err


# ------------------------------------------------------------------------------------ run


@pytest.mark.parametrize("overwrite", [(), ("--overwrite",)], ids=["plain", "overwrite"])
def test_run_never_deletes_a_photo_beside_run_files(monkeypatch, capsys, tmp_path, short_run,
                                                    overwrite):  # fmt: skip
    """The issue's case: {log.csv, run.json, photo.png} without a marker is the user's."""
    out = tmp_path / "mine"
    out.mkdir()
    for name in ("log.csv", "run.json"):
        shutil.copyfile(short_run / name, out / name)
    (out / "photo.png").write_bytes(b"\x89PNG user's photo")
    before = _snapshot(out)
    _refused(monkeypatch, capsys, "run", "paper-ideal", *SHORT, "--out", str(out), *overwrite,
             fragment="holds files auvmpc did not write")  # fmt: skip
    assert _snapshot(out) == before


def test_run_overwrite_keeps_a_file_the_user_put_in_a_subfolder(monkeypatch, capsys, run_folder):
    (run_folder / "notes").mkdir()
    (run_folder / "notes" / "todo.txt").write_text("mine")
    before = _snapshot(run_folder)
    _refused(monkeypatch, capsys, "run", "paper-ideal", *SHORT, "--out", str(run_folder),
             "--overwrite", fragment="notes")  # fmt: skip
    assert _snapshot(run_folder) == before


@pytest.mark.parametrize(
    ("name", "message"),
    [
        ("../../../x", "name: becomes a folder name: no '/'"),
        ("/tmp/absolute", "name: becomes a folder name: no '/'"),
        ('"a\\0b"', "name: becomes a folder name: no '/', '\\', NUL"),
        ("n" * 300, "name: too long for a folder name (300 bytes"),
        ("..", "name: is not a name a folder can have"),
    ],
    ids=["dotdot", "absolute", "nul", "300-characters", "parent"],
)
def test_a_scenario_name_is_never_a_path(monkeypatch, capsys, tmp_path, name, message):
    (tmp_path / "work").mkdir()
    monkeypatch.chdir(tmp_path / "work")
    _refused(monkeypatch, capsys, "run", "paper-ideal", *SHORT, "--set", f"name={name}",
             fragment=f"error: {message}")  # fmt: skip
    assert [p.name for p in tmp_path.rglob("*")] == ["work"]  # nothing written anywhere


def test_os_errors_on_the_output_are_one_line_naming_the_path(monkeypatch, capsys, tmp_path):
    """Disk full while writing log.csv (simulated: no small filesystem needed)."""
    import auvmpc.experiments.run as run_module

    def full(path, text):
        raise OSError(errno.ENOSPC, "No space left on device", str(path))

    monkeypatch.setattr(run_module, "atomic_write_text", full)
    out = tmp_path / "run"
    err = _refused(monkeypatch, capsys, "run", "paper-ideal", *SHORT, "--out", str(out),
                   fragment="No space left on device")  # fmt: skip
    assert f"cannot write {out}/log.csv" in err  # the path meant, not the staging folder
    assert list(tmp_path.iterdir()) == []


def test_a_read_only_run_folder_is_one_line_for_animate(monkeypatch, capsys, run_folder):
    """Read-only (simulated: the tests may run as root, whom permissions do not stop)."""
    import tempfile

    def read_only(*args, dir=None, **kwargs):
        raise OSError(errno.EROFS, "Read-only file system", str(dir))

    monkeypatch.setattr(tempfile, "mkstemp", read_only)
    before = _snapshot(run_folder)
    _refused(monkeypatch, capsys, "animate", str(run_folder),
             fragment=f"cannot write {run_folder / MARKER}: Read-only file system")  # fmt: skip
    assert _snapshot(run_folder) == before


def test_a_full_disk_under_the_campaign_store_is_one_line(tmp_path):
    """SQLite's own codes for a refused write (FULL, IOERR, READONLY...) become the line;
    others (a busy database) stay what they are."""
    from auvmpc.errors import ConfigError
    from auvmpc.experiments.campaign.store import _storage_errors

    def failure(message, code):
        error = sqlite3.OperationalError(message)
        error.sqlite_errorcode = code  # as SQLite sets it
        return error

    path = tmp_path / "results.sqlite"
    with pytest.raises(ConfigError, match=rf"^--out: cannot write {path}: database or disk"):
        with _storage_errors(path):
            raise failure("database or disk is full", 13)
    with pytest.raises(sqlite3.OperationalError, match="locked"):
        with _storage_errors(path):
            raise failure("database is locked", 5)


def test_a_name_too_long_and_a_parent_that_is_a_file_are_one_line(monkeypatch, capsys, tmp_path):
    run = ("run", "paper-ideal", *SHORT, "--out")
    _refused(monkeypatch, capsys, *run, str(tmp_path / ("n" * 300)), fragment="too long for a")
    (tmp_path / "file").write_text("mine")
    _refused(monkeypatch, capsys, *run, str(tmp_path / "file" / "r"), fragment="is a file")
    assert (tmp_path / "file").read_text() == "mine"


def test_a_symbolic_link_as_out_is_refused(monkeypatch, capsys, tmp_path, run_folder):
    link = tmp_path / "link"
    link.symlink_to(run_folder)
    before = _snapshot(run_folder)
    _refused(monkeypatch, capsys, "run", "paper-ideal", *SHORT, "--out", str(link), "--overwrite",
             fragment="is a symbolic link")  # fmt: skip
    assert _snapshot(run_folder) == before and link.is_symlink()


def test_a_link_put_in_place_of_an_own_folder_after_the_check_is_left_alone(monkeypatch, tmp_path):
    """--overwrite moved a link aside as if it were the folder, and removing a folder does
    not remove a link: it stayed as a stale .partial link. A link put in place after the
    last check (the only way past it) is now put back and refused at the move itself."""
    from auvmpc.errors import ConfigError
    from auvmpc.experiments import outputs

    out, elsewhere = tmp_path / "run", tmp_path / "elsewhere"
    for folder in (out, elsewhere):
        with staged_folder(folder, OutputKind.RUN, overwrite=False) as staging:
            (staging / "log.csv").write_text("t\n")
    check, swap = outputs.check_output_folder, []

    def check_then_link(path, *args, **kwargs):
        checked = check(path, *args, **kwargs)
        if swap:  # after the last check, before the move: a link takes the folder's place
            shutil.rmtree(out)
            out.symlink_to(elsewhere)
        return checked

    monkeypatch.setattr(outputs, "check_output_folder", check_then_link)
    before = _snapshot(elsewhere)
    with pytest.raises(ConfigError, match="is a symbolic link"):
        with staged_folder(out, OutputKind.RUN, overwrite=True) as staging:
            (staging / "log.csv").write_text("t\n")
            swap.append(True)
    assert out.is_symlink() and _snapshot(elsewhere) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["elsewhere", "run"]  # no .partial


# ----------------------------------------------------------------------- a real full disk


def _on_small_disk(request, tmp_path, body) -> None:
    """``body(disk)`` with ``disk`` a real 256 KiB tmpfs: the kernel's own ENOSPC, not a stub.

    Mounted in place where root may mount; elsewhere this test runs again, by pytest, in a
    user and mount namespace (``unshare -rm``), whose root may; skipped where neither can.
    """
    if os.environ.get("AUVMPC_TEST_TMPFS"):  # that run, inside the namespace
        body(Path(os.environ["AUVMPC_TEST_TMPFS"]))
        return
    disk = tmp_path / "disk"
    disk.mkdir()
    mount = f"mount -t tmpfs -o size=256k tmpfs {shlex.quote(str(disk))}"
    here = subprocess.run(["sh", "-c", mount], capture_output=True, text=True)
    if here.returncode == 0:
        try:
            body(disk)
        finally:
            subprocess.run(["umount", "-l", str(disk)], check=True)
        return
    inside = ["unshare", "-rm", "sh", "-c", mount + ' && exec "$@"', "sh"]
    try:
        probe = subprocess.run([*inside, "true"], capture_output=True, text=True)
        why = (probe.stderr.strip() or f"exit {probe.returncode}") if probe.returncode else ""
    except FileNotFoundError:
        why = "no unshare command"
    if why:
        pytest.skip(f"no tmpfs to fill: mount: {here.stderr.strip()}; unshare -rm: {why}")
    again = subprocess.run(
        [*inside, sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
         request.node.nodeid],
        env={**os.environ, "AUVMPC_TEST_TMPFS": str(disk)}, cwd=request.config.rootpath,
        capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert again.returncode == 0 and "1 passed" in again.stdout, again.stdout + again.stderr


def _free_kib(disk) -> int:
    space = os.statvfs(disk)
    return space.f_bavail * space.f_frsize // 1024


def _fill(disk, free_kib: int) -> None:
    """Fill ``disk`` up to ``free_kib`` KiB of free space."""
    filler = disk / "filler"
    filler.unlink(missing_ok=True)
    with open(filler, "wb") as stream:
        os.posix_fallocate(stream.fileno(), 0, (_free_kib(disk) - free_kib) * 1024)


def test_a_full_disk_is_one_line_and_leaves_nothing(request, monkeypatch, capsys, tmp_path,
                                                    short_run):  # fmt: skip
    """A run out of space at each of its files (0, 8, 16 KiB free: the marker, log.csv,
    run.json), and --overwrite of an earlier run: one line naming the file meant and the
    system's reason, exit 2, no staging folder left, the earlier run as it was."""

    def body(disk):
        out = disk / "run"
        for free in (0, 8, 16):
            _fill(disk, free)
            err = _refused(monkeypatch, capsys, "run", "paper-ideal", *SHORT, "--out", str(out),
                           fragment="No space left on device")  # fmt: skip
            assert f"cannot write {out}/" in err
            assert [p.name for p in disk.iterdir()] == ["filler"]
        (disk / "filler").unlink()
        shutil.copytree(short_run, out)
        before = _snapshot(out)
        _fill(disk, 8)
        _refused(monkeypatch, capsys, "run", "paper-ideal", *SHORT, "--out", str(out),
                 "--overwrite", fragment="No space left on device")  # fmt: skip
        assert _snapshot(out) == before
        assert sorted(p.name for p in disk.iterdir()) == ["filler", "run"]

    _on_small_disk(request, tmp_path, body)


def test_a_bag_the_full_disk_cannot_list_is_not_left(request, monkeypatch, capsys, tmp_path,
                                                     short_run):  # fmt: skip
    """``export`` into a run folder short of space for its marker (0 KiB free), the bag
    (half of what it takes) and the marker's listing of the bag (room for the bag only;
    the new marker is written beside the old): the bag fitted, its listing did not, and
    the bag stayed, a stranger that made a later ``run --overwrite`` there refuse. Now
    each is one line, and the folder holds what it held; one page more, and it is written."""

    def body(disk):
        probe = shutil.copytree(short_run, disk / "probe")
        free = _free_kib(disk)
        assert run_cli(monkeypatch, capsys, "export", str(probe))[0] == 0
        needed = free - _free_kib(disk)  # what the bag takes
        shutil.rmtree(probe)
        folder = shutil.copytree(short_run, disk / "run")
        before = {path: data for path, data in _snapshot(folder).items() if path != MARKER}
        for free, where in ((0, MARKER), (needed // 2, ""), (needed, MARKER)):
            _fill(disk, free)
            err = _refused(monkeypatch, capsys, "export", str(folder),
                           fragment="No space left on device")  # fmt: skip
            assert f"cannot write {folder / where}" in err
            assert {p: d for p, d in _snapshot(folder).items() if p != MARKER} == before
            check_output_folder(folder, OutputKind.RUN, overwrite=True)  # nothing unlisted
        _fill(disk, needed + os.statvfs(disk).f_bsize // 1024)
        assert run_cli(monkeypatch, capsys, "export", str(folder))[0] == 0

    _on_small_disk(request, tmp_path, body)


# ------------------------------------------------------------------------------ reproduce


def _reproduction(folder):
    """An own reproduction folder, made without running it (runs/<name> marked as runs)."""
    with staged_folder(folder, OutputKind.REPRODUCE, overwrite=False) as staging:
        run = staging / "runs" / "paper-ideal--mpc"
        run.mkdir(parents=True)
        (run / "log.csv").write_text("t\n")
        mark_folder(run, OutputKind.RUN)
        (staging / "summary.md").write_text("| a |\n")
    return folder


@pytest.mark.parametrize("overwrite", [(), ("--overwrite",)], ids=["plain", "overwrite"])
def test_reproduce_never_deletes_a_users_file_in_runs(monkeypatch, capsys, tmp_path, overwrite):
    out = _reproduction(tmp_path / "paper")
    check_output_folder(out, OutputKind.REPRODUCE, overwrite=True)  # all of it auvmpc's
    (out / "runs" / "run1.txt").write_text("mine")
    before = _snapshot(out)
    fragment = "runs/run1.txt" if overwrite else "add --overwrite"
    _refused(monkeypatch, capsys, "reproduce", "--no-sweep", "--no-figures", "--out", str(out),
             *overwrite, fragment=fragment)  # fmt: skip
    assert _snapshot(out) == before


def test_a_file_added_to_a_run_of_a_reproduction_is_listed_by_that_run(tmp_path):
    from auvmpc.experiments.outputs import adding

    out = _reproduction(tmp_path / "paper")
    with adding(out / "runs" / "paper-ideal--mpc", ["animation.gif"], "RUN_DIR") as run:
        (run / "animation.gif").write_bytes(b"GIF89a")
    check_output_folder(out, OutputKind.REPRODUCE, overwrite=True)  # the run's marker lists it


def test_reproduce_refuses_a_folder_that_only_looks_like_one(monkeypatch, capsys, tmp_path):
    out = tmp_path / "paper"
    (out / "runs").mkdir(parents=True)
    (out / "summary.md").write_text("my own summary")
    before = _snapshot(out)
    _refused(monkeypatch, capsys, "reproduce", "--no-sweep", "--out", str(out), "--overwrite",
             fragment="holds files auvmpc did not write")  # fmt: skip
    assert _snapshot(out) == before


# -------------------------------------------------------------------------------- compare


def test_compare_never_deletes_a_users_folder_holding_comparison_json(
    monkeypatch, capsys, tmp_path, run_folder
):
    out = tmp_path / "mine"
    (out / "chapter").mkdir(parents=True)
    (out / "comparison.json").write_text("{}")
    (out / "notes.md").write_text("mine")
    before = _snapshot(out)
    _refused(monkeypatch, capsys, "compare", str(run_folder), str(run_folder), "--out", str(out),
             fragment="holds files auvmpc did not write")  # fmt: skip
    assert _snapshot(out) == before


def test_compare_into_its_own_folder_keeps_a_file_the_user_added(
    monkeypatch, capsys, tmp_path, run_folder
):
    out = tmp_path / "cmp"
    runs = (str(run_folder), str(run_folder))
    code, _, err = run_cli(monkeypatch, capsys, "compare", *runs, "--dpi", "20", "--out", str(out))
    assert code == 0, err
    check_output_folder(out, OutputKind.COMPARE, overwrite=True)  # its own: compare replaces it
    (out / "notes.md").write_text("mine")
    before = _snapshot(out)
    _refused(monkeypatch, capsys, "compare", *runs, "--out", str(out), fragment="notes.md")
    assert _snapshot(out) == before


# ------------------------------------------------------------------------------- campaign


def _user_database(path):
    with sqlite3.connect(path) as db:
        db.execute("CREATE TABLE thesis (x REAL)")
        db.execute("INSERT INTO thesis VALUES (1.5)")
    db.close()


@pytest.mark.parametrize("overwrite", [(), ("--overwrite",)], ids=["plain", "overwrite"])
@pytest.mark.parametrize("case", ["results.sqlite", "lock-and-report"])
def test_campaign_never_writes_into_a_users_database_or_report(
    monkeypatch, capsys, tmp_path, case, overwrite
):
    out = tmp_path / "mine"
    out.mkdir()
    if case == "results.sqlite":
        _user_database(out / "results.sqlite")
    else:
        (out / ".campaign.lock").write_text("")
        (out / "report.md").write_text("my report")
    before = _snapshot(out)
    _refused(monkeypatch, capsys, *CAMPAIGN, str(out), *overwrite,
             fragment="holds files auvmpc did not write")  # fmt: skip
    assert _snapshot(out) == before


def test_campaign_overwrite_keeps_a_file_the_user_added(monkeypatch, capsys, tmp_path):
    from tests.test_campaign import campaign_folder

    out = campaign_folder(tmp_path / "c")
    (out / "report.md").write_text("mine")
    before = _snapshot(out)
    _refused(monkeypatch, capsys, *CAMPAIGN, str(out), "--overwrite", fragment="report.md")
    assert _snapshot(out) == before


def test_a_campaign_report_is_never_written_over_a_users_file(monkeypatch, capsys, tmp_path):
    """campaign-report claims its files in the marker: a user's report.md is refused; the
    report auvmpc writes is its own, so --overwrite of the campaign then succeeds."""
    from tests.test_campaign import with_changes, write_campaign

    file = write_campaign(tmp_path, with_changes(runs=1, overrides=["duration=2"]))
    out = tmp_path / "c"
    code, _, err = run_cli(monkeypatch, capsys, "campaign", str(file), "--workers", "1",
                           "--out", str(out), "--no-report")  # fmt: skip
    assert code == 0, err
    (out / "report.md").write_text("mine")
    _refused(monkeypatch, capsys, "campaign-report", str(out), "--no-figures",
             fragment="holds report.md, which auvmpc did not write")  # fmt: skip
    assert (out / "report.md").read_text() == "mine" and not (out / "report.json").exists()
    (out / "report.md").unlink()
    code, _, err = run_cli(monkeypatch, capsys, "campaign-report", str(out), "--no-figures")
    assert code == 0, err
    check_output_folder(out, OutputKind.CAMPAIGN, overwrite=True)  # all of it auvmpc's


# ------------------------------------------------------------- animate, plot, export (added later)


def test_animate_never_replaces_a_users_file(monkeypatch, capsys, tmp_path, run_folder):
    (run_folder / "animation.gif").write_bytes(b"GIF89a user's")
    elsewhere = tmp_path / "movie.gif"
    elsewhere.write_bytes(b"GIF89a user's too")
    before, other = _snapshot(run_folder), elsewhere.read_bytes()
    _refused(monkeypatch, capsys, "animate", str(run_folder),
             fragment="holds animation.gif, which auvmpc did not write")  # fmt: skip
    _refused(monkeypatch, capsys, "animate", str(run_folder), "--out", str(elsewhere),
             fragment="exists")  # fmt: skip
    assert _snapshot(run_folder) == before and elsewhere.read_bytes() == other


def test_animate_then_run_overwrite_succeeds(monkeypatch, capsys, run_folder):
    """Issue 30: an animation is auvmpc's own file of the run folder."""
    code, _, err = run_cli(monkeypatch, capsys, "animate", str(run_folder), "--dpi", "20")
    assert code == 0, err
    assert "animation.gif" in json.loads((run_folder / MARKER).read_text())["files"]
    assert run_cli(monkeypatch, capsys, "animate", str(run_folder), "--dpi", "20")[0] == 0
    code, _, err = run_cli(monkeypatch, capsys, "run", "paper-ideal", *SHORT,
                           "--out", str(run_folder), "--overwrite")  # fmt: skip
    assert code == 0, err
    assert not (run_folder / "animation.gif").exists()


def test_plot_never_replaces_a_users_pdf(monkeypatch, capsys, run_folder):
    (run_folder / "trajectory.pdf").write_bytes(b"%PDF user's")
    before = _snapshot(run_folder)
    _refused(monkeypatch, capsys, "plot", str(run_folder), "--format", "pdf",
             fragment="trajectory.pdf, which auvmpc did not write")  # fmt: skip
    assert _snapshot(run_folder) == before


def test_export_bag_is_auvmpcs_and_never_over_a_users_folder(monkeypatch, capsys, run_folder):
    pytest.importorskip("rosbags")
    (run_folder / "rosbag2").mkdir()
    (run_folder / "rosbag2" / "mine.txt").write_text("mine")
    before = _snapshot(run_folder)
    _refused(monkeypatch, capsys, "export", str(run_folder), fragment="exists")
    assert _snapshot(run_folder) == before
    shutil.rmtree(run_folder / "rosbag2")
    code, _, err = run_cli(monkeypatch, capsys, "export", str(run_folder))
    assert code == 0, err
    listed = json.loads((run_folder / MARKER).read_text())["files"]
    assert "rosbag2" in listed and "rosbag2/metadata.yaml" in listed
    code, _, err = run_cli(monkeypatch, capsys, "run", "paper-ideal", *SHORT,
                           "--out", str(run_folder), "--overwrite")  # fmt: skip
    assert code == 0, err


# ------------------------------------------------------------------------------- export-c


@pytest.mark.parametrize("overwrite", [(), ("--overwrite",)], ids=["plain", "overwrite"])
def test_export_c_never_touches_a_users_file(monkeypatch, capsys, tmp_path, overwrite):
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "main.c").write_text("int main(void) { return 0; }\n")
    own = tmp_path / "own"
    with staged_folder(own, OutputKind.EXPORT_C, overwrite=False) as staging:
        (staging / "auvmpc_config.h").write_text("/* auvmpc's */\n")
    (own / "main.c").write_text("int main(void) { return 0; }\n")
    before = _snapshot(tmp_path)
    _refused(monkeypatch, capsys, "export-c", "paper-ideal", "--out", str(mine), *overwrite,
             fragment="holds files auvmpc did not write")  # fmt: skip
    fragment = "main.c" if overwrite else "add --overwrite"
    _refused(monkeypatch, capsys, "export-c", "paper-ideal", "--out", str(own), *overwrite,
             fragment=fragment)  # fmt: skip
    assert _snapshot(tmp_path) == before


def test_a_run_folder_of_an_earlier_version_is_still_auvmpcs_to_replace(
    tmp_path, monkeypatch, capsys
):
    """A format-1 marker (before the marker listed every path) lists the names its run wrote:
    those are auvmpc's, so --overwrite replaces such a folder; a file it does not list is
    the user's, and the folder is refused naming it."""
    folder = tmp_path / "old-run"
    folder.mkdir()
    for name in ("log.csv", "run.json"):
        (folder / name).write_text("old\n")
    (folder / MARKER).write_text(
        json.dumps({"kind": "run", "files": [MARKER, "log.csv", "run.json"]})
    )
    code, _, _ = run_cli(monkeypatch, capsys, "run", "paper-ideal", "--set", "duration=2",
                         "--no-figures", "--out", str(folder), "--overwrite")  # fmt: skip
    assert code == 0 and (folder / "log.csv").read_text() != "old\n"
    (folder / "notes.txt").write_text("mine\n")
    marker = folder / MARKER
    marker.write_text(json.dumps({"kind": "run", "files": [MARKER, "log.csv", "run.json"]}))
    code, _, stderr = run_cli(monkeypatch, capsys, "run", "paper-ideal", "--set", "duration=2",
                              "--no-figures", "--out", str(folder), "--overwrite")  # fmt: skip
    assert code == 2 and "notes.txt" in stderr
    assert (folder / "notes.txt").read_text() == "mine\n"
