"""Fetch a BLASFEO built for x86-64 with AVX2 and FMA (BLASFEO's X64_INTEL_HASWELL target),
for ``auvmpc export-c --blasfeo DIR`` on this kind of machine.

The casadi wheel's BLASFEO is the portable GENERIC build. PyPI's ``comma-deps-acados``
wheel ships a BLASFEO built for X64_INTEL_HASWELL with its headers; this script downloads
that wheel (a pinned version, from the package registry, not installed: it also carries a
casadi of its own that must not replace auvmpc's) and unpacks only ``libblasfeo.so`` and
``blasfeo_target.h`` into DIR. Run it once; nothing is fetched at run time.

    python benchmarks/blasfeo_haswell.py --out .venv/blasfeo-x64-haswell
    auvmpc export-c paper-obstacles --blasfeo .venv/blasfeo-x64-haswell --out X
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from pinned_wheel import empty_folder_or_exit, unpack_members

WHEEL = "comma-deps-acados==0.2.2.post92"  # its BLASFEO: TARGET_X64_INTEL_HASWELL
# pip checks the download against this (the wheel measured on 2026-11-24), so a replaced
# file on the registry is refused rather than unpacked
WHEEL_SHA256 = "fb317ea65c68d410e19b46f824c333203a097d02dac6fbbdc1f378c2b32b456f"
MEMBERS = {
    "acados/install/lib/libblasfeo.so": "libblasfeo.so",
    "acados/install/include/blasfeo/include/blasfeo_target.h": "blasfeo_target.h",
}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, required=True, help="folder to unpack into")
    out = parser.parse_args().out
    empty_folder_or_exit(out)
    missing = unpack_members(WHEEL, WHEEL_SHA256, "manylinux_2_28_x86_64", MEMBERS, out)
    if missing:
        print(f"error: {WHEEL} no longer holds {missing}", file=sys.stderr)
        return 1
    print(f"wrote {out}: {', '.join(MEMBERS.values())}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
