"""Where auvmpc may write, and how: never over anything it did not write itself.

The rule, for every command that writes a folder (``run``, ``reproduce``, ``campaign``,
``plot``):

- a new folder, or an existing empty one, is written;
- a folder carrying auvmpc's own marker file (:data:`MARKER`, or the files of an
  auvmpc folder written before the marker existed) is replaced only with
  ``--overwrite``, and only if it holds nothing but what auvmpc wrote there; a
  campaign folder is resumed without it;
- anything else (a user's folder, a file, the filesystem root) is refused with one
  line, touching nothing.

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
import tempfile
import uuid
from collections.abc import Iterator
from datetime import UTC, datetime
from enum import StrEnum
from pathlib import Path

from auvmpc import __version__
from auvmpc.errors import ConfigError

__all__ = [
    "MARKER",
    "OutputKind",
    "atomic_write_text",
    "check_output_file",
    "check_output_folder",
    "mark_folder",
    "own_kind",
    "record_written",
    "prepare_campaign_folder",
    "require_own_folder",
    "staged_folder",
]

MARKER = ".auvmpc-output.json"
_PARTIAL = re.compile(r"^\.(?P<name>.+)\.(?P<pid>\d+)\.[0-9a-f]{8}\.partial$")


class OutputKind(StrEnum):
    RUN = "run"
    REPRODUCE = "reproduce"
    CAMPAIGN = "campaign"
    EXPORT_C = "export-c"


# What each kind of folder holds at its top level, for folders written before the marker
# existed (recognised as auvmpc's own) and for campaigns, whose files change as they run.
_LEGACY_NAMES = {
    OutputKind.RUN: re.compile(r"^(log\.csv|run\.json|[\w.-]+\.png)$"),
    OutputKind.REPRODUCE: re.compile(
        r"^(runs|summary\.(md|csv|json)|depth\.(md|json)|error_vs_uncertainty\.png)$"
    ),
    OutputKind.CAMPAIGN: re.compile(
        r"^(results\.sqlite(-wal|-shm|-journal)?|\.campaign\.lock|report[\w.-]*\.(md|json)"
        r"|figures[\w.-]*)$"
    ),
    OutputKind.EXPORT_C: re.compile(r"^[\w.-]+\.(c|h|txt|json|md)$|^Makefile$"),
}
_LEGACY_REQUIRED = {  # any one of these sets of names marks the kind
    OutputKind.RUN: ({"run.json", "log.csv"},),
    OutputKind.REPRODUCE: ({"summary.md", "runs"},),
    OutputKind.CAMPAIGN: ({"results.sqlite"}, {".campaign.lock"}),
    OutputKind.EXPORT_C: (),  # written with the marker from the start: no older form
}


def _marker(folder: Path) -> dict | None:
    try:
        data = json.loads((folder / MARKER).read_text())
    except (OSError, ValueError, UnicodeDecodeError):
        return None
    if not isinstance(data, dict) or data.get("kind") not in set(OutputKind):
        return None
    return data


def own_kind(folder: Path) -> OutputKind | None:
    """The kind of auvmpc output ``folder`` is, or None if auvmpc did not write it."""
    folder = Path(folder)
    if not folder.is_dir():
        return None
    marker = _marker(folder)
    if marker is not None:
        return OutputKind(marker["kind"])
    names = {entry.name for entry in folder.iterdir()}
    for kind, pattern in _LEGACY_NAMES.items():
        if all(pattern.match(name) for name in names) and any(
            required <= names for required in _LEGACY_REQUIRED[kind]
        ):
            return kind
    return None


def _strangers(folder: Path, kind: OutputKind) -> list[str]:
    """Top-level entries of an own folder that auvmpc did not write there."""
    marker = _marker(folder) or {}
    written = marker.get("files")
    if kind is OutputKind.CAMPAIGN or written is None:  # names a folder of this kind holds
        pattern = _LEGACY_NAMES[kind]
        return sorted(
            e.name for e in folder.iterdir() if e.name != MARKER and not pattern.match(e.name)
        )
    return sorted(e.name for e in folder.iterdir() if e.name not in {*written, MARKER})


def _absolute(path: Path, option: str) -> Path:
    path = Path(os.path.abspath(Path(path).expanduser()))
    if path.parent == path:
        raise ConfigError(option, str(path), "is the filesystem root; name a folder to write")
    for ancestor in path.parents:
        if ancestor.exists():
            if not ancestor.is_dir():
                raise ConfigError(option, str(path), f"{ancestor} is a file, not a folder")
            break
    return path


_NOUN = {
    OutputKind.RUN: "run",
    OutputKind.REPRODUCE: "reproduction",
    OutputKind.CAMPAIGN: "campaign",
    OutputKind.EXPORT_C: "C export",
}


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
        ``path`` is a file, the root, a non-empty folder auvmpc did not write, auvmpc's
        folder of another kind, or auvmpc's own folder without ``overwrite`` (and without
        ``resume``), or one holding files auvmpc did not write.
    """
    target = _absolute(Path(path), option)
    shown = str(path)
    if target.exists() or target.is_symlink():
        if not target.is_dir():
            raise ConfigError(option, shown, "is a file, not a folder; name a new folder")
        if not any(target.iterdir()):
            return target
        found = own_kind(target)
        if found is None:
            raise ConfigError(
                option, shown, "holds files auvmpc did not write; name a new or empty folder"
            )
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
        strangers = _strangers(target, kind)
        if strangers:
            raise ConfigError(
                option,
                shown,
                f"also holds files auvmpc did not write ({', '.join(strangers[:3])}); "
                "move them or name another folder",
            )
    return target


def require_own_folder(path: Path | str, kind: OutputKind, option: str) -> Path:
    """``path`` must be an existing folder auvmpc wrote as ``kind`` (e.g. to redraw into)."""
    folder = Path(path)
    if not folder.is_dir():
        raise ConfigError(option, str(path), f"not a {_NOUN[kind]} folder (no such folder)")
    found = own_kind(folder)
    if found is not kind:
        raise ConfigError(option, str(path), f"not a {_NOUN[kind]} folder written by auvmpc")
    return folder


def check_output_file(path: Path | str, *, overwrite: bool, option: str) -> Path:
    """A file to write: its folder must exist as a folder; an existing file needs
    ``overwrite``; a folder is refused."""
    target = _absolute(Path(path), option)
    if target.is_dir():
        raise ConfigError(option, str(path), "is a folder; name a file")
    if target.exists() and not overwrite:
        raise ConfigError(option, str(path), "exists; add --overwrite to replace it")
    return target


def _write_marker(folder: Path, kind: OutputKind, files: list[str] | None = None) -> None:
    data = {
        "kind": str(kind),
        "auvmpc_version": __version__,
        "written_utc": datetime.now(UTC).isoformat(timespec="seconds"),
        "pid": os.getpid(),
        "files": sorted(files) if files is not None else None,
    }
    atomic_write_text(folder / MARKER, json.dumps(data, indent=2) + "\n")


def record_written(folder: Path, kind: OutputKind, names: list[str]) -> None:
    """Add ``names`` (written into an own folder after the fact, e.g. redrawn figures) to
    its marker, so that ``--overwrite`` later knows them as auvmpc's."""
    marker = _marker(folder)
    if marker is None:  # a folder from before the marker: everything in it is auvmpc's
        _write_marker(folder, kind, [entry.name for entry in folder.iterdir()])
    elif marker.get("files") is not None:
        _write_marker(folder, kind, sorted({*marker["files"], *names}))


def mark_folder(folder: Path, kind: OutputKind) -> None:
    """Mark a finished folder inside a staged one (e.g. a run folder of a reproduction)."""
    _write_marker(folder, kind, [entry.name for entry in folder.iterdir()])


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


@contextlib.contextmanager
def staged_folder(path: Path | str, kind: OutputKind, *, overwrite: bool) -> Iterator[Path]:
    """Write a ``kind`` folder all or nothing.

    Yields a hidden staging folder next to ``path``; when the block ends normally the
    staging folder gets its final marker and replaces ``path`` (checked again first).
    On any exception, interrupts included, it is removed and ``path`` is untouched.
    """
    target = check_output_folder(path, kind, overwrite=overwrite)
    parent = target.parent
    parent.mkdir(parents=True, exist_ok=True)
    clean_stale_partials(parent, target.name)
    staging = parent / f".{target.name}.{os.getpid()}.{uuid.uuid4().hex[:8]}.partial"
    staging.mkdir()
    try:
        _write_marker(staging, kind)  # first, so a killed write is recognisably ours
        yield staging
        _write_marker(staging, kind, [entry.name for entry in staging.iterdir()])
        check_output_folder(path, kind, overwrite=overwrite)  # nobody wrote there meanwhile
        _replace(staging, target)
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise


def _replace(staging: Path, target: Path) -> None:
    if target.is_dir() and any(target.iterdir()):  # an own folder, --overwrite given
        retired = target.with_name(f".{target.name}.{os.getpid()}.{uuid.uuid4().hex[:8]}.partial")
        os.replace(target, retired)
        os.replace(staging, target)
        shutil.rmtree(retired, ignore_errors=True)
    else:  # absent or empty: rename(2) replaces an empty folder and refuses a full one
        os.replace(staging, target)


def prepare_campaign_folder(path: Path | str, *, overwrite: bool) -> Path:
    """Create (or accept for resuming) a campaign folder; with ``overwrite`` an existing
    campaign folder is emptied first (only if it holds nothing but auvmpc's files)."""
    target = check_output_folder(path, OutputKind.CAMPAIGN, overwrite=overwrite, resume=True)
    if overwrite and own_kind(target) is OutputKind.CAMPAIGN:
        check_output_folder(path, OutputKind.CAMPAIGN, overwrite=True)  # no strangers
        retired = target.with_name(f".{target.name}.{os.getpid()}.{uuid.uuid4().hex[:8]}.partial")
        os.replace(target, retired)
        shutil.rmtree(retired, ignore_errors=True)
    target.mkdir(parents=True, exist_ok=True)
    if _marker(target) is None:
        _write_marker(target, OutputKind.CAMPAIGN)
    return target


def _umask() -> int:
    """The process umask, read without changing it where /proc allows."""
    with contextlib.suppress(OSError, ValueError):
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("Umask:"):
                return int(line.split()[1], 8)
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def atomic_write_text(path: Path | str, text: str) -> None:
    """Write a file so that readers see the old content or the new, never a part.

    The file gets the user's normal permissions (0666 minus the umask), like any file
    the user creates, not the private mode of a temporary file.
    """
    path = Path(path)
    handle, temporary = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        os.fchmod(handle, 0o666 & ~_umask())
        with os.fdopen(handle, "w") as stream:
            stream.write(text)
            stream.flush()
            os.fsync(stream.fileno())
        os.replace(temporary, path)
    except BaseException:
        Path(temporary).unlink(missing_ok=True)
        raise
