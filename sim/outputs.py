"""Files a flattening run writes: layout (OBJ/SVG), history CSV, plot PNG.

Every writer goes through :func:`atomic_write`, so an interrupted or failed
run never leaves a partial file behind.
"""

from __future__ import annotations

import csv
import math
import os
import tempfile
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator

import numpy as np

from golden_model.mesh import save_obj
from golden_model.reference import FlattenResult

HISTORY_HEADER = ("iteration", "dt", "area_error", "shape_error", "energy", "flipped")
LAYOUT_SUFFIXES = (".obj", ".svg")


class OutputError(ValueError):
    """An output path that cannot be written; one line for the user."""


def check_output_path(path: Path, what: str, suffixes: tuple[str, ...] | None = None) -> None:
    """Fail early (before a long run) on an output path that cannot work."""
    if suffixes and path.suffix.lower() not in suffixes:
        raise OutputError(f"{what} '{path}' must end in {' or '.join(suffixes)}")
    parent = path.parent if str(path.parent) else Path(".")
    if not parent.is_dir():
        raise OutputError(f"{what} '{path}': directory '{parent}' does not exist")
    if path.is_dir():
        raise OutputError(f"{what} '{path}' is a directory")


@contextmanager
def atomic_write(path: Path, mode: str = "w") -> Iterator[str]:
    """Yield a temporary path next to ``path``; rename it over ``path`` on success."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".part", dir=path.parent or ".")
    os.close(fd)
    try:
        yield tmp
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


def write_layout(path: Path, positions: np.ndarray, faces: np.ndarray) -> None:
    """The layout as OBJ (z = 0, same faces) or, for ``.svg``, as an SVG drawing."""
    with atomic_write(path) as tmp:
        if Path(path).suffix.lower() == ".svg":
            _write_svg(tmp, positions, faces)
        else:
            save_obj(tmp, positions, faces)


def _write_svg(path: str, positions: np.ndarray, faces: np.ndarray) -> None:
    """Triangles as SVG polygons in mesh units (y up, as in the plots)."""
    lo, hi = positions.min(axis=0), positions.max(axis=0)
    size = float(max(hi - lo)) or 1.0
    margin = 0.02 * size
    stroke = 0.002 * size
    flipped = positions * np.array([1.0, -1.0])  # SVG's y axis points down
    x0, y0 = lo[0] - margin, -hi[1] - margin
    width, height = hi[0] - lo[0] + 2 * margin, hi[1] - lo[1] + 2 * margin
    with open(path, "w", encoding="utf-8") as out:
        out.write('<?xml version="1.0" encoding="UTF-8"?>\n')
        out.write(f'<svg xmlns="http://www.w3.org/2000/svg" viewBox="{x0:.9g} {y0:.9g} {width:.9g} {height:.9g}">\n')
        out.write(f'<g fill="#dfe8f5" stroke="#1f3b73" stroke-width="{stroke:.6g}" stroke-linejoin="round">\n')
        for face in faces:
            points = " ".join(f"{x:.9g},{y:.9g}" for x, y in flipped[face])
            out.write(f'<polygon points="{points}"/>\n')
        out.write("</g>\n</svg>\n")


def write_history(path: Path, result: FlattenResult) -> None:
    """CSV of :data:`HISTORY_HEADER`, row 0 = initial layout (empty ``dt``)."""
    with atomic_write(path) as tmp, open(tmp, "w", newline="", encoding="utf-8") as out:
        writer = csv.writer(out)
        writer.writerow(HISTORY_HEADER)
        for k, dt, area, shape, energy, flipped in result.history.rows():
            writer.writerow([k, "" if math.isnan(dt) else repr(dt), repr(area), repr(shape), repr(energy), flipped])


def write_plot(path: Path, result: FlattenResult, faces: np.ndarray, title: str = "") -> None:
    """PNG: initial and final layouts overlaid (paper Figs. 8/10), error curves (Figs. 11/12)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax_layout, ax_errors) = plt.subplots(1, 2, figsize=(11, 4.8))
    for positions, colour, label in (
        (result.initial_positions, "tab:blue", "initial layout"),
        (result.positions, "tab:red", f"after {result.iterations} iterations"),
    ):
        ax_layout.triplot(positions[:, 0], positions[:, 1], faces, color=colour, lw=0.8, label=label)
    ax_layout.set_aspect("equal")
    ax_layout.legend(loc="upper right", fontsize=8)
    ax_layout.set_title("layouts")
    k = np.arange(len(result.history))
    ax_errors.plot(k, result.history.area_error, "-", color="tab:green", label="area error $E_S$")
    ax_errors.plot(k, result.history.shape_error, "-", color="tab:purple", label="shape error $E_C$")
    params = result.params
    ax_errors.axhline(params.tol_area, color="tab:green", ls=":", lw=0.8)
    ax_errors.axhline(params.tol_shape, color="tab:purple", ls=":", lw=0.8)
    ax_errors.set_xlabel("iteration")
    ax_errors.set_ylabel("relative error")
    ax_errors.set_title(f"{params.step} step, {result.status}")
    ax_errors.legend(fontsize=8)
    ax_errors.grid(alpha=0.3)
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    with atomic_write(path) as tmp:
        fig.savefig(tmp, dpi=110, format="png")
    plt.close(fig)
