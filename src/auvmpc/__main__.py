"""``python -m auvmpc``: the command line, as ``auvmpc``."""

from auvmpc.cli import main

main()
