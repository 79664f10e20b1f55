"""Where a result came from: when, how long, which command, which code and libraries.

The keys are a contract (``shared/spec/interfaces.md``, run.json ``provenance``):
``started_utc``, ``wall_s``, ``command``, ``auvmpc_version``, ``git_revision`` (or
null) and ``libraries`` (distribution name -> version).
"""

from __future__ import annotations

import functools
import shlex
import subprocess
import sys
import time
from collections.abc import Iterable
from dataclasses import dataclass, field
from datetime import UTC, datetime
from importlib import metadata
from pathlib import Path
from typing import Any

from auvmpc import __version__

__all__ = ["BASE_LIBRARIES", "Stopwatch", "command_line", "git_revision", "library_versions"]

# Every run uses these; the QP solver or do-mpc a controller uses is added by name.
BASE_LIBRARIES = ("numpy", "scipy", "casadi")


def command_line() -> str:
    """The command as typed: ``auvmpc run ...`` from the CLI, else the Python argv."""
    argv = list(sys.argv)
    if argv and Path(argv[0]).name == "auvmpc":
        argv[0] = "auvmpc"
    return shlex.join(argv)


@functools.cache
def git_revision() -> str | None:
    """The commit of the auvmpc checkout this code runs from (``+dirty`` with local
    changes), or None when it is installed from a package or git is unavailable."""
    source = Path(__file__).resolve().parents[1]  # the auvmpc package folder
    try:
        head = subprocess.run(
            ["git", "-C", str(source), "rev-parse", "HEAD"],
            capture_output=True, text=True, timeout=5, check=True,
        ).stdout.strip()  # fmt: skip
        dirty = subprocess.run(
            ["git", "-C", str(source), "status", "--porcelain", "--untracked-files=no", "."],
            capture_output=True, text=True, timeout=5, check=True,
        ).stdout.strip()  # fmt: skip
    except (OSError, subprocess.SubprocessError):
        return None
    return f"{head}+dirty" if dirty else head or None


def library_versions(extra: Iterable[str] = ()) -> dict[str, str | None]:
    """Installed versions of numpy, scipy, casadi and ``extra`` (None if not installed)."""
    return {name: _installed_version(name) for name in (*BASE_LIBRARIES, *extra)}


@functools.cache  # reading package metadata costs ~2 ms a package, and a process keeps them
def _installed_version(name: str) -> str | None:
    try:
        return metadata.version(name)
    except metadata.PackageNotFoundError:
        return None


@dataclass
class Stopwatch:
    """Start time (UTC, wall clock) and elapsed time of one piece of work."""

    started_utc: str = field(
        default_factory=lambda: datetime.now(UTC).isoformat(timespec="milliseconds")
    )
    _started: float = field(default_factory=time.perf_counter)

    def record(self, libraries: Iterable[str] = ()) -> dict[str, Any]:
        """The ``provenance`` mapping, with the wall time up to now."""
        return {
            "started_utc": self.started_utc,
            "wall_s": time.perf_counter() - self._started,
            "command": command_line(),
            "auvmpc_version": __version__,
            "git_revision": git_revision(),
            "libraries": library_versions(libraries),
        }
