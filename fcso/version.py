"""fcso's version, read from the installed package's metadata (as ``trimesh/version.py`` does).

A module of its own, so that recording the version loads nothing else of fcso.
"""

from importlib.metadata import PackageNotFoundError, version


def _installed_version() -> str:
    try:
        return version("fcso")
    except PackageNotFoundError:
        # run from a source tree that was never installed
        return "0+unknown"


__version__ = _installed_version()
