"""Where auvmpc may write, and how: never over anything it did not write itself.

Every command that writes (``run``, ``reproduce``, ``bench --out``, ``compare``, ``campaign``,
``campaign-report``, ``plot``, ``animate``, ``export``, ``export-c``) goes through this
module. The rule:

- a new folder, or an existing empty one, is written;
- a folder carrying auvmpc's marker file (:data:`MARKER`) is replaced only with
  ``--overwrite`` (``compare`` replaces its own without), and only if it holds nothing
  but what the marker lists; a campaign folder is resumed without it;
- a file added later to auvmpc's folder (an animation, a bag, redrawn figures, a
  campaign report) is listed in the marker before it is written; an existing file of
  that name is replaced only if the marker already lists it;
- anything else (a user's folder or file, the filesystem root, a symbolic link) is
  refused with one line, touching nothing.

Ownership comes from the marker only: it lists every file and folder auvmpc wrote, by
path relative to the marked folder (a folder inside with a marker of its own, such as a
run folder of a reproduction, lists its own). Nothing is recognised by its name or
contents. Operating-system errors on the output (read-only, permission denied, disk
full, a name too long) become one line naming the path.

Results are staged in a hidden sibling folder ``.<name>.<pid>.<token>.partial`` that
carries the marker from its first moment and is renamed into place when complete, so an
interrupted or killed command never leaves a folder that looks finished. Stale staging
folders of a process that is gone are removed on the next write into the same place.
"""

from __future__ import annotations

import contextlib
import json
import os
import re
import shutil
import uuid
from collections.abc import Iterable, Iterator
from datetime import UTC, datetime
from enum import StrEnum
from pathlib import Path

from auvmpc import __version__
from auvmpc.atomic_write import atomic_write_text
from auvmpc.errors import ConfigError

__all__ = [
    "MARKER",
    "MAX_NAME_BYTES",
    "OutputKind",
    "adding",
    "atomic_write_text",
    "cannot_write",
    "claim",
    "check_output_file",
    "check_output_folder",
    "folder_name",
    "mark_folder",
    "new_entry",
    "output_errors",
    "own_kind",
    "prepare_campaign_folder",
    "require_own_folder",
    "staged_folder",
    "write_named_file",
]

MARKER = ".auvmpc-output.json"
# The marker's layout: 2 lists every path; 1 (no "format" key) listed the top-level names
# a run or reproduction wrote, and nothing for a campaign (_listed says what counts).
MARKER_FORMAT = 2
_PARTIAL = re.compile(r"^\.(?P<name>.+)\.(?P<pid>\d+)\.[0-9a-f]{8}\.partial$")
# A folder name must leave room for its staging name ".<name>.<pid>.<token>.partial"
# within the 255 bytes most filesystems allow for one name.
MAX_NAME_BYTES = 255 - len(".4194304.01234567.partial") - 1
_UNSAFE_CHARACTERS = re.compile(r"[/\\\x00-\x1f\x7f]")
# SQLite's own companions of a database file (write-ahead log, shared memory, journal).
_SQLITE_COMPANIONS = ("-wal", "-shm", "-journal")


class OutputKind(StrEnum):
    RUN = "run"
    REPRODUCE = "reproduce"
    CAMPAIGN = "campaign"
    EXPORT_C = "export-c"
    COMPARE = "compare"
    BENCH = "bench"


_NOUN = {
    OutputKind.RUN: "run",
    OutputKind.REPRODUCE: "reproduction",
    OutputKind.CAMPAIGN: "campaign",
    OutputKind.EXPORT_C: "C export",
    OutputKind.COMPARE: "comparison",
    OutputKind.BENCH: "benchmark",
}


@contextlib.contextmanager
def output_errors(
    option: str, shown: str, staging: Path | None = None, target: Path | None = None
) -> Iterator[None]:
    """Operating-system errors on the output as one line naming the path (a staging
    path shown as the path it stands for)."""
    try:
        yield
    except OSError as error:
        where = error.filename if error.filename is not None else target or shown
        if staging is not None and target is not None:
            if not str(where).startswith(str(target.parent)):
                raise  # not the output's (e.g. a preset read while the block computes)
            where = str(where).replace(str(staging), str(target))
        raise cannot_write(option, shown, where, error.strerror or type(error).__name__) from None


def cannot_write(option: str, shown: str, where: Path | str, reason: str) -> ConfigError:
    """The one line for output that the system refuses to take (also a database's)."""
    return ConfigError(option, shown, f"cannot write {where}: {reason}")


def folder_name(text: str, field: str) -> str:
    """``text`` as one file or folder name (e.g. a scenario name in the default run
    folder): never a path, so nothing is written outside the folder meant.

    Raises
    ------
    ConfigError
        Empty, ``.`` or ``..``, a ``/``, ``\\``, NUL or other control character, or more
        than :data:`MAX_NAME_BYTES` bytes of UTF-8.
    """
    if text in ("", ".", ".."):
        raise ConfigError(field, text, "is not a name a folder can have")
    if _UNSAFE_CHARACTERS.search(text):
        raise ConfigError(
            field, text, "becomes a folder name: no '/', '\\', NUL or control characters"
        )
    size = len(text.encode("utf-8", "surrogateescape"))
    if size > MAX_NAME_BYTES:
        raise ConfigError(
            field, text, f"too long for a folder name ({size} bytes, at most {MAX_NAME_BYTES})"
        )
    return text


def _marker(folder: Path) -> dict | None:
    try:
        data = json.loads((folder / MARKER).read_text())
    except (OSError, ValueError, UnicodeDecodeError):
        return None
    if not isinstance(data, dict) or data.get("kind") not in set(OutputKind):
        return None
    return data


def _listed(marker: dict) -> set[str] | None:
    """The paths a marker lists, or None for an older marker that lists none (a campaign's
    before format 2). A format-1 marker (no ``format``) lists the names it wrote at its
    folder's top level, which is what a run folder of that time holds, so a run or a
    reproduction written by an earlier version can still be replaced; anything else in such
    a folder is a stranger, and the folder is refused by name."""
    files = marker.get("files")
    if marker.get("format", 1) not in (1, MARKER_FORMAT) or not isinstance(files, list):
        return None
    return {name for name in files if isinstance(name, str)}


def own_kind(folder: Path) -> OutputKind | None:
    """The kind of auvmpc output ``folder`` is (from its marker), or None."""
    folder = Path(folder)
    if not folder.is_dir() or folder.is_symlink():
        return None
    marker = _marker(folder)
    return None if marker is None else OutputKind(marker["kind"])


def _owns(listed: set[str], relative: str) -> bool:
    if relative in listed:
        return True
    return any(relative == f"{name}{suffix}" for name in listed for suffix in _SQLITE_COMPANIONS)


def _strangers(folder: Path) -> list[str]:
    """Paths in an own folder that its marker (or a marker further in) does not list."""
    found: list[str] = []

    def walk(directory: Path, base: Path, listed: set[str]) -> None:
        for entry in sorted(directory.iterdir()):
            if directory == base and entry.name == MARKER:
                continue
            if not _owns(listed, entry.relative_to(base).as_posix()):
                found.append(entry.relative_to(folder).as_posix())
            elif entry.is_dir() and not entry.is_symlink():
                inner = _marker(entry)
                inner_listed = None if inner is None else _listed(inner)
                if inner_listed is not None:
                    walk(entry, entry, inner_listed)
                else:
                    walk(entry, base, listed)

    walk(folder, folder, _listed(_marker(folder) or {}) or set())
    return found


def _all_paths(folder: Path, entries: Iterable[Path]) -> list[str]:
    """``entries`` and everything in those that are folders, relative to ``folder``."""
    paths = []
    for entry in entries:
        paths.append(entry.relative_to(folder).as_posix())
        if entry.is_dir() and not entry.is_symlink():
            paths += [inner.relative_to(folder).as_posix() for inner in entry.rglob("*")]
    return paths


def _absolute(path: Path, option: str) -> Path:
    path = Path(os.path.abspath(Path(path).expanduser()))
    if path.parent == path:
        raise ConfigError(option, str(path), "is the filesystem root; name a folder to write")
    folder_name(path.name, option)
    for ancestor in path.parents:
        if ancestor.exists():
            if not ancestor.is_dir():
                raise ConfigError(option, str(path), f"{ancestor} is a file, not a folder")
            break
    return path


def _shown(names: list[str]) -> str:
    more = f" and {len(names) - 3} more" if len(names) > 3 else ""
    return ", ".join(names[:3]) + more


def check_output_folder(
    path: Path | str,
    kind: OutputKind,
    *,
    overwrite: bool,
    option: str = "--out",
    resume: bool = False,
) -> Path:
    """Check that ``path`` may be written as a ``kind`` folder; return it as absolute path.

    Raises
    ------
    ConfigError
        ``path`` is a file, a symbolic link, the root, a non-empty folder without auvmpc's
        marker, auvmpc's folder of another kind, or auvmpc's own folder without
        ``overwrite`` (and without ``resume``), or one holding anything its marker does
        not list.
    """
    shown = str(path)
    with output_errors(option, shown):
        target = _absolute(Path(path), option)
        if target.is_symlink():
            raise ConfigError(option, shown, _SYMBOLIC_LINK)
        if not target.exists():
            return target
        if not target.is_dir():
            raise ConfigError(option, shown, "is a file, not a folder; name a new folder")
        if not any(target.iterdir()):
            return target
        marker = _marker(target)
        if marker is None:
            raise ConfigError(
                option, shown, "holds files auvmpc did not write; name a new or empty folder"
            )
        found = OutputKind(marker["kind"])
        if found is not kind:
            raise ConfigError(
                option,
                shown,
                f"is an auvmpc {_NOUN[found]} folder, not a {_NOUN[kind]} folder; name another",
            )
        if resume:
            return target
        if not overwrite:
            raise ConfigError(
                option,
                shown,
                f"holds an earlier auvmpc {_NOUN[kind]}; add --overwrite to replace it",
            )
        _refuse_strangers(target, marker, option, shown)
    return target


_SYMBOLIC_LINK = "is a symbolic link; name the folder itself"
_OLDER_MARKER = (
    "was written by an earlier auvmpc whose marker does not list its files; "
    "remove it yourself or name another folder"
)


def _refuse_strangers(folder: Path, marker: dict, option: str, shown: str) -> None:
    if _listed(marker) is None:
        raise ConfigError(option, shown, _OLDER_MARKER)
    strangers = _strangers(folder)
    if strangers:
        raise ConfigError(
            option,
            shown,
            f"also holds files auvmpc did not write ({_shown(strangers)}); "
            "move them or name another folder",
        )


def require_own_folder(path: Path | str, kind: OutputKind, option: str) -> Path:
    """``path`` must be an existing folder auvmpc wrote as ``kind`` (e.g. to redraw into)."""
    folder = Path(path)
    if not folder.is_dir():
        raise ConfigError(option, str(path), f"not a {_NOUN[kind]} folder (no such folder)")
    if own_kind(folder) is not kind:
        marker = folder / MARKER
        if marker.is_file() and _marker(folder) is None:
            raise ConfigError(
                option, str(marker), f"the marker {MARKER} is damaged (not auvmpc's JSON record "
                "of what it wrote): auvmpc cannot tell this folder is its own",
            )  # fmt: skip
        raise ConfigError(option, str(path), f"not a {_NOUN[kind]} folder written by auvmpc")
    return folder


def check_output_file(path: Path | str, *, overwrite: bool, option: str) -> Path:
    """A file the user names to write: its folder must exist as a folder; an existing file
    needs ``overwrite``; a folder is refused."""
    with output_errors(option, str(path)):
        target = _absolute(Path(path), option)
        if target.is_dir():
            raise ConfigError(option, str(path), "is a folder; name a file")
        if target.exists() and not overwrite:
            raise ConfigError(option, str(path), "exists; add --overwrite to replace it")
    return target


def write_named_file(path: Path | str, text: str, *, option: str) -> None:
    """Write the file the user named (checked first with :func:`check_output_file`)
    atomically; an operating-system error is one line naming it."""
    with output_errors(option, str(path)):
        atomic_write_text(path, text)


def _write_marker(folder: Path, kind: OutputKind, files: Iterable[str]) -> None:
    data = {
        "kind": str(kind),
        "format": MARKER_FORMAT,
        "auvmpc_version": __version__,
        "written_utc": datetime.now(UTC).isoformat(timespec="seconds"),
        "pid": os.getpid(),
        "files": sorted(set(files) - {MARKER}),
    }
    atomic_write_text(folder / MARKER, json.dumps(data, indent=2) + "\n")


def mark_folder(folder: Path, kind: OutputKind) -> None:
    """Mark a finished folder inside a staged one (e.g. a run folder of a reproduction)."""
    _write_marker(folder, kind, _all_paths(folder, (e for e in folder.iterdir())))


def claim(folder: Path | str, names: Iterable[str], option: str) -> OutputKind:
    """List entries ``names`` (files or folders, top level) in the marker of auvmpc's own
    ``folder`` before they are written, so that they count as auvmpc's. Returns the
    folder's kind.

    Raises
    ------
    ConfigError
        ``folder`` has no marker of the current layout, or holds one of ``names``
        that the marker does not list (auvmpc never writes into or over it).
    """
    folder = Path(folder)
    names = list(names)
    shown = str(folder)
    with output_errors(option, shown):
        for name in names:
            folder_name(name, option)
        marker = _marker(folder)
        if marker is None:
            raise ConfigError(option, shown, "not a folder auvmpc wrote; name another")
        listed = _listed(marker)
        if listed is None:
            raise ConfigError(option, shown, _OLDER_MARKER)
        taken = [n for n in names if (folder / n).exists() and not _owns(listed, n)]
        if taken:
            raise ConfigError(
                option,
                shown,
                f"holds {_shown(taken)}, which auvmpc did not write; move it or write elsewhere",
            )
        kind = OutputKind(marker["kind"])
        _write_marker(folder, kind, {*listed, *names})
    return kind


@contextlib.contextmanager
def adding(folder: Path | str, names: Iterable[str], option: str) -> Iterator[Path]:
    """Write entries ``names`` into auvmpc's own ``folder`` in the block: claimed first
    (:func:`claim`, so a killed write is recognisably auvmpc's); when the block ends,
    those that exist are listed with whatever the named folders hold, and a name the
    block did not write is no longer claimed. If the block or that listing fails, the
    entries the block created are removed. Operating-system errors become one line."""
    folder = Path(folder)
    names = list(names)
    before = _listed(_marker(folder) or {}) or set()
    new = [n for n in names if not os.path.lexists(folder / n)]
    kind = claim(folder, names, option)

    def list_written() -> None:
        entries = [folder / n for n in names if (folder / n).exists()]
        kept = (_listed(_marker(folder) or {}) or set()) - (set(names) - before)
        _write_marker(folder, kind, {*kept, *_all_paths(folder, entries)})

    try:
        with output_errors(option, str(folder)):
            yield folder
            list_written()
    except BaseException:
        # All or nothing, like a staged folder: a new entry the marker could not list
        # (a full disk) would be a stranger in auvmpc's own folder, and a later
        # --overwrite there refused.
        for name in new:
            _remove(folder / name)
        with contextlib.suppress(OSError):
            list_written()
        raise


def _remove(path: Path) -> None:
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path, ignore_errors=True)
    else:
        path.unlink(missing_ok=True)


@contextlib.contextmanager
def new_entry(path: Path | str, option: str) -> Iterator[Path]:
    """A file or folder ``path`` to create: listed in its folder's marker if auvmpc wrote
    that folder (:func:`adding`, so an own earlier one is replaced); elsewhere it must not
    exist. Yields ``path``."""
    shown = str(path)
    with output_errors(option, shown):
        target = _absolute(Path(path), option)
    if own_kind(target.parent) is not None:
        with adding(target.parent, [target.name], option):
            yield Path(path)
        return
    with output_errors(option, shown):
        if target.exists() or target.is_symlink():
            raise ConfigError(option, shown, "exists; remove it or choose another name")
        target.parent.mkdir(parents=True, exist_ok=True)
        yield Path(path)


def _pid_alive(pid: int) -> bool:
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def clean_stale_partials(parent: Path, name: str) -> list[Path]:
    """Remove staging folders ``.<name>.<pid>.<token>.partial`` in ``parent`` whose
    process is gone and that carry auvmpc's marker (or are empty). Returns those removed."""
    removed = []
    if not parent.is_dir():
        return removed
    for entry in parent.iterdir():
        match = _PARTIAL.match(entry.name)
        if not match or match["name"] != name or not entry.is_dir() or entry.is_symlink():
            continue
        if _pid_alive(int(match["pid"])):
            continue
        if _marker(entry) is not None:
            shutil.rmtree(entry, ignore_errors=True)
            removed.append(entry)
        else:
            with contextlib.suppress(OSError):
                entry.rmdir()  # only if empty: never delete what is not ours
                removed.append(entry)
    return removed


def _staging_name(target: Path) -> Path:
    return target.with_name(f".{target.name}.{os.getpid()}.{uuid.uuid4().hex[:8]}.partial")


@contextlib.contextmanager
def staged_folder(
    path: Path | str, kind: OutputKind, *, overwrite: bool, option: str = "--out"
) -> Iterator[Path]:
    """Write a ``kind`` folder all or nothing.

    Yields a hidden staging folder next to ``path``; when the block ends normally the
    staging folder gets its final marker (listing everything in it) and replaces ``path``
    (checked again first). On any exception, interrupts included, it is removed and
    ``path`` is untouched; an operating-system error becomes one line naming the path.
    """
    target = check_output_folder(path, kind, overwrite=overwrite, option=option)
    staging = _staging_name(target)
    try:
        with output_errors(option, str(path), staging, target):
            target.parent.mkdir(parents=True, exist_ok=True)
            clean_stale_partials(target.parent, target.name)
            staging.mkdir()
            _write_marker(staging, kind, [])  # first, so a killed write is recognisably ours
            yield staging
            _write_marker(staging, kind, _all_paths(staging, staging.iterdir()))
            check_output_folder(path, kind, overwrite=overwrite, option=option)  # meanwhile?
            _replace(staging, target, option, str(path))
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise


def _replace(staging: Path, target: Path, option: str, shown: str) -> None:
    if not target.is_symlink() and not (target.is_dir() and any(target.iterdir())):
        os.replace(staging, target)  # rename(2) replaces an empty folder, refuses a full one
        return
    retired = _retire(target, option, shown)  # an own folder, --overwrite given
    os.replace(staging, target)
    shutil.rmtree(retired, ignore_errors=True)


def _retire(target: Path, option: str, shown: str) -> Path:
    """Move auvmpc's own folder ``target`` aside (to be removed), checked again there,
    where nobody else writes: a file added or a symbolic link put in its place since the
    check is put back and refused (a link moved aside stayed as a stale ``.partial``
    link, which removing a folder does not remove)."""
    retired = _staging_name(target)
    os.replace(target, retired)
    try:
        if retired.is_symlink():
            raise ConfigError(option, shown, _SYMBOLIC_LINK)
        _refuse_strangers(retired, _marker(retired) or {}, option, shown)
    except ConfigError:
        os.replace(retired, target)
        raise
    return retired


def prepare_campaign_folder(
    path: Path | str, *, overwrite: bool, files: Iterable[str], option: str = "--out"
) -> Path:
    """Create (or accept for resuming) a campaign folder whose marker lists ``files`` (the
    campaign's store and lock, before they are created); with ``overwrite`` an existing
    campaign folder is discarded first (only if it holds nothing its marker does not list).
    """
    target = check_output_folder(path, OutputKind.CAMPAIGN, overwrite=overwrite, resume=True)
    shown = str(path)
    with output_errors(option, shown, target=target):
        if overwrite and own_kind(target) is OutputKind.CAMPAIGN:
            check_output_folder(path, OutputKind.CAMPAIGN, overwrite=True, option=option)
            shutil.rmtree(_retire(target, option, shown), ignore_errors=True)
        target.mkdir(parents=True, exist_ok=True)
        if _marker(target) is None:
            _write_marker(target, OutputKind.CAMPAIGN, [])
    claim(target, files, option)
    return target
