"""gndreplay: replay 2D laser + odometry logs through a GND / ND+ navigation stack, tick by tick."""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("gndreplay")
except PackageNotFoundError:  # pragma: no cover - running from a source tree without install
    __version__ = "0.0.0+src"

__all__ = ["__version__"]
