"""Unpack a few files of a wheel fetched from the package registry by a pinned version and
sha256, without installing it: the setup steps ``make blasfeo`` (blasfeo_tuned.py), ``make
blasfeo-avx`` (blasfeo_avx.py) and ``make hpipm-aarch64`` (hpipm_aarch64.py) use it; nothing
is fetched at run time."""

from __future__ import annotations

import subprocess
import sys
import tempfile
import zipfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path


@contextmanager
def pinned_wheel(requirement: str, sha256: str | None, platform: str) -> Iterator[zipfile.ZipFile]:
    """The wheel ``requirement`` (``name==version``) for ``platform``, downloaded into a
    scratch folder and checked by pip against ``sha256`` (None: against the hash the registry
    publishes for it, which pip checks on every download); removed on leaving."""
    with tempfile.TemporaryDirectory() as scratch:
        pinned = Path(scratch) / "requirement.txt"
        pinned.write_text(
            requirement + ("" if sha256 is None else f" --hash=sha256:{sha256}") + "\n"
        )
        hashes = () if sha256 is None else ("--require-hashes",)
        subprocess.run(
            [sys.executable, "-m", "pip", "download", "--quiet", "--no-deps", *hashes,
             "--only-binary", ":all:", "--platform", platform, "-d", scratch, "-r", str(pinned)],
            check=True,
        )  # fmt: skip
        (wheel,) = Path(scratch).glob("*.whl")
        with zipfile.ZipFile(wheel) as archive:
            yield archive


def unpack_members(
    requirement: str, sha256: str | None, platform: str, members: dict[str, str], out: Path
) -> list[str]:
    """Download ``requirement`` as :func:`pinned_wheel` does and write each archive member
    whose name ends with a key of ``members`` into ``out`` under that key's value. Returns
    the values not found in the wheel."""
    with pinned_wheel(requirement, sha256, platform) as archive:
        out.mkdir(parents=True, exist_ok=True)
        for name in archive.namelist():
            for suffix, target in members.items():
                if name.endswith(suffix):
                    (out / target).write_bytes(archive.read(name))
    return [target for target in members.values() if not (out / target).is_file()]


def empty_folder_or_exit(out: Path) -> None:
    """Refuse (exit 2, one line) an ``--out`` that exists and is not an empty folder."""
    if out.exists() and (not out.is_dir() or any(out.iterdir())):
        print(f"error: --out: {out} exists and is not an empty folder", file=sys.stderr)
        raise SystemExit(2)
