"""The installed springflat's version (``springflat --version``, ``springflat.__version__``, the bundles'
``reproduce.sh``) and where its packages sit."""

from __future__ import annotations

from pathlib import Path

#: The directory holding the ``golden_model``, ``hdl`` and ``sim`` packages: the checkout, for the README's
#: set-up (its ``build/``, the paths Amaranth writes into ``src`` attributes).
SOURCE_ROOT = Path(__file__).resolve().parents[1]


def installed_version() -> str:
    """The installed distribution's version (``pyproject.toml``), or a word saying it is not installed."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("springflat")
    except PackageNotFoundError:
        return "(not installed: run 'make test' or 'make demo')"
