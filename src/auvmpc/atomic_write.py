"""Writing a file so that its readers never see a part of it (every writer of auvmpc's)."""

from __future__ import annotations

import contextlib
import os
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import IO

__all__ = ["atomic_file", "atomic_write_text"]


def _umask() -> int:
    """The process umask, read without changing it where /proc allows."""
    with contextlib.suppress(OSError, ValueError):
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("Umask:"):
                return int(line.split()[1], 8)
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


@contextlib.contextmanager
def atomic_file(path: Path | str, mode: str = "w") -> Iterator[IO]:
    """A stream whose content replaces ``path`` when the block ends, all or nothing.

    Written to a hidden temporary file beside ``path`` and renamed onto it, so readers see
    the old content or the new, never a part; on any exception the temporary file is
    removed. An operating-system error (a full disk) names ``path``, not the temporary
    file. The file gets the user's normal permissions (0666 minus the umask), like any
    file the user creates, not the private mode of a temporary file.
    """
    path = Path(path)
    try:
        handle, temporary = tempfile.mkstemp(
            prefix=f".{path.name}.", suffix=".tmp", dir=path.parent
        )
    except OSError as error:  # name the file meant, not the temporary one
        raise OSError(error.errno, error.strerror, str(path)) from None
    try:
        os.fchmod(handle, 0o666 & ~_umask())
        with os.fdopen(handle, mode) as stream:
            yield stream
            stream.flush()
            os.fsync(stream.fileno())
        os.replace(temporary, path)
    except OSError as error:
        Path(temporary).unlink(missing_ok=True)
        raise OSError(error.errno, error.strerror, str(path)) from None
    except BaseException:
        Path(temporary).unlink(missing_ok=True)
        raise


def atomic_write_text(path: Path | str, text: str) -> None:
    """Write a text file so that readers see the old content or the new, never a part
    (:func:`atomic_file`)."""
    with atomic_file(path) as stream:
        stream.write(text)
