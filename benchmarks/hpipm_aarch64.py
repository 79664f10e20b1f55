"""Fetch the aarch64 (64-bit Arm) HPIPM and BLASFEO that ``auvmpc export-c --aarch64 DIR``
puts into an export, so that it builds with ``make TARGET=aarch64`` (docs/onboard.md).

They are the shared libraries of the casadi wheel for manylinux2014_aarch64 of the version
auvmpc runs with (the same HPIPM and BLASFEO releases, built for a generic ARMv8-A, BLASFEO's
GENERIC target, as the installed x86-64 wheel's), with their BSD-2-Clause licences. This
script downloads that wheel (pinned by sha256, from the package registry, not installed) and
unpacks only those files into DIR. Run it once; nothing is fetched at run time.

    python benchmarks/hpipm_aarch64.py --out .venv/hpipm-aarch64
    auvmpc export-c paper-obstacles --aarch64 .venv/hpipm-aarch64 --out X
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import casadi
from pinned_wheel import empty_folder_or_exit, unpack_members

# pip checks each download against these (the wheels measured on 2026-11-27)
WHEEL_SHA256 = {
    "3.8.2": "9a3e1a496c538000790491bde6e01a8c419c90f7d52b65c89455f37eccef786c",
}
MEMBERS = {
    "casadi/libhpipm.so": "libhpipm.so",
    "casadi/libblasfeo.so.0": "libblasfeo.so.0",
    "casadi/libdaqp.so": "libdaqp.so",
    "casadi/include/blasfeo_target.h": "blasfeo_target.h",
    "licenses/hpipm-external/LICENSE.txt": "HPIPM-LICENSE.txt",
    "licenses/blasfeo-external/LICENSE.txt": "BLASFEO-LICENSE.txt",
    "licenses/daqp-external/LICENSE": "DAQP-LICENSE.txt",
}
VERSION_FILE = "casadi-version"  # export-c checks it against the casadi it runs with


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, required=True, help="folder to unpack into")
    out = parser.parse_args().out
    version = casadi.__version__
    if version not in WHEEL_SHA256:
        # A casadi release newer than this file (pyproject allows a range): its aarch64 wheel
        # of the same version, checked against the registry's own hash rather than failing.
        known = ", ".join(WHEEL_SHA256)
        print(f"note: casadi {version}: no sha256 pinned here (known: {known}); the "
              "registry's hash checks it", file=sys.stderr)  # fmt: skip
    empty_folder_or_exit(out)
    requirement = f"casadi=={version}"
    missing = unpack_members(
        requirement, WHEEL_SHA256.get(version), "manylinux2014_aarch64", MEMBERS, out
    )
    if missing:
        print(f"error: {requirement} for aarch64 holds no {missing}", file=sys.stderr)
        return 1
    (out / VERSION_FILE).write_text(version + "\n")
    print(f"wrote {out}: {', '.join(MEMBERS.values())}, {VERSION_FILE}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
