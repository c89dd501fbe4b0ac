"""The installed springflat's version: ``springflat --version``, ``springflat.__version__``, the bundles'
``reproduce.sh``."""

from __future__ import annotations


def installed_version() -> str:
    """The installed distribution's version (``pyproject.toml``), or a word saying it is not installed."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("springflat")
    except PackageNotFoundError:
        return "(not installed: run 'make test' or 'make demo')"
