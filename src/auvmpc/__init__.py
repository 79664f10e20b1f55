"""auvmpc: model-predictive trajectory tracking for autonomous underwater vehicles.

The public Python API (:mod:`auvmpc.api`) is available from the package itself,
``auvmpc.load_scenario``, ``auvmpc.simulate``, ..., imported on first use so that
``import auvmpc`` (and the command line) stays quick.
"""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("auvmpc")
except PackageNotFoundError:  # running from a source tree without install
    __version__ = "0.0.0+unknown"

_API = (
    "build_controller",
    "controller_overrides",
    "figures",
    "load_run",
    "load_scenario",
    "log_dataframe",
    "override",
    "save_run",
    "session",
    "simulate",
)

__all__ = ["__version__", *_API]


def __getattr__(name: str):
    if name in _API:
        from auvmpc import api

        return getattr(api, name)
    raise AttributeError(f"module 'auvmpc' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(__all__)
