"""auvmpc: model-predictive trajectory tracking for autonomous underwater vehicles."""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("auvmpc")
except PackageNotFoundError:  # running from a source tree without install
    __version__ = "0.0.0+unknown"

__all__ = ["__version__"]
