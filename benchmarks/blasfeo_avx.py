"""Build a BLASFEO for x86-64 with AVX and neither AVX2 nor FMA (BLASFEO's
X64_INTEL_SANDY_BRIDGE target), for ``auvmpc export-c --generic-blasfeo DIR``: the generic
x86-64 build's BLASFEO on every CPU it runs on (the casadi wheel's HPIPM in that build
already needs AVX, docs/onboard.md), where the wheel's GENERIC BLASFEO is plain C.

No package on the registry ships that build; PyPI's ``rockit-meco`` wheel carries BLASFEO's
sources (in acados's tree it vendors). This script downloads that wheel (a pinned version,
checked by pip against its sha256; not installed), unpacks only BLASFEO's folder, builds it
with this computer's gcc and cmake for that target, and writes ``libblasfeo.so``,
``blasfeo_target.h`` and BLASFEO's ``LICENSE.txt`` (BSD-2-Clause) into DIR. Run it once, at
setup (``make blasfeo-avx``); nothing is fetched or built at run time.

    python benchmarks/blasfeo_avx.py --out .venv/blasfeo-x64-sandy-bridge
    auvmpc export-c paper-obstacles --generic-blasfeo .venv/blasfeo-x64-sandy-bridge --out X
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

from pinned_wheel import empty_folder_or_exit, pinned_wheel

WHEEL = "rockit-meco==0.6.7"
# the wheel measured on 2026-11-27 (py3-none-any): pip refuses a replaced file on the registry
SHA256 = "9bcc22ab32aaa2078b5affcdffc80208db278405b7c0fa2bb6354e03b4e3df6d"
SOURCES = "rockit/external/acados/external/external/blasfeo/"
TARGET = "X64_INTEL_SANDY_BRIDGE"
# BLASFEO's own API only (HPIPM calls nothing else), as a shared library
CMAKE_OPTIONS = [f"-DTARGET={TARGET}", "-DBUILD_SHARED_LIBS=ON", "-DBLAS_API=OFF",
                 "-DBLASFEO_EXAMPLES=OFF", "-DCMAKE_BUILD_TYPE=Release"]  # fmt: skip


def _unpack_sources(into: Path) -> None:
    """BLASFEO's source folder from the pinned wheel into ``into``."""
    with pinned_wheel(WHEEL, SHA256, "manylinux_2_28_x86_64") as archive:
        members = [name for name in archive.namelist() if name.startswith(SOURCES)]
        if not members:
            print(f"error: {WHEEL} no longer holds {SOURCES}", file=sys.stderr)
            raise SystemExit(1)
        for name in members:
            if not name.endswith("/"):
                path = into / name.removeprefix(SOURCES)
                path.parent.mkdir(parents=True, exist_ok=True)
                path.write_bytes(archive.read(name))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, required=True, help="folder to write into")
    out = parser.parse_args().out
    empty_folder_or_exit(out)
    for tool in ("cmake", "gcc"):
        if shutil.which(tool) is None:
            print(f"error: {tool} not found: building BLASFEO needs it", file=sys.stderr)
            return 1
    with tempfile.TemporaryDirectory() as scratch:
        source, build, install = (Path(scratch) / name for name in ("src", "build", "install"))
        _unpack_sources(source)
        jobs = str(os.cpu_count() or 1)
        for command in (
            ["cmake", "-S", source, "-B", build, f"-DCMAKE_INSTALL_PREFIX={install}",
             *CMAKE_OPTIONS],
            ["cmake", "--build", build, "-j", jobs],
            ["cmake", "--install", build],
        ):  # fmt: skip
            subprocess.run(command, check=True, stdout=subprocess.DEVNULL)
        header = install / "include" / "blasfeo_target.h"
        if f"#define TARGET_{TARGET}\n" not in header.read_text():
            print(f"error: the build's {header.name} does not name {TARGET}", file=sys.stderr)
            return 1
        out.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(install / "lib" / "libblasfeo.so", out / "libblasfeo.so")
        shutil.copyfile(header, out / header.name)
        shutil.copyfile(source / "LICENSE.txt", out / "LICENSE.txt")
    print(f"wrote {out}: libblasfeo.so ({TARGET}), blasfeo_target.h, LICENSE.txt")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
