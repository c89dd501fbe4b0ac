"""The paper's appendix meshes Surf1 and Surf2 with their parameter sets.

Coordinates and faces are copied from the paper's appendix (A.1, A.2), where
faces are 1-based; they are converted to 0-based here.  The parameter sets
are the paper's Tables II (Surf1) and IV (Surf2); both use ``C = 0.5`` and
``rho = 2``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .mesh import Mesh
from .params import FlattenParams

__all__ = ["BUILTIN_MESHES", "PaperParameters", "builtin_mesh", "is_builtin"]


@dataclass(frozen=True)
class PaperParameters:
    """A parameter set of the paper (Tables II and IV)."""

    spring: float
    density: float
    tol_area: float
    tol_shape: float
    tol_energy: float
    max_iter: int
    #: iterations the paper reports for the fixed and the variable step.
    paper_iterations_fixed: int
    paper_iterations_variable: int

    def flatten_params(self, **changes) -> FlattenParams:
        """The run's parameters: the paper dynamics with this set's C, ρ, φ_S, φ_C, ε and N_max, and ``changes``."""
        return FlattenParams(spring=self.spring, density=self.density, tol_area=self.tol_area,
                             tol_shape=self.tol_shape, tol_energy=self.tol_energy, max_iter=self.max_iter, **changes)


_SURF1_VERTICES = [
    [0.3, 0.4, 1], [0.6, 0.5, 1], [0.2, 0.2, 0], [0.1, 0.6, 0],
    [0.4, 0.9, 0], [0.8, 0.7, 0], [0.7, 0.3, 0],
]  # fmt: skip
_SURF1_FACES_1BASED = [[6, 5, 2], [6, 2, 7], [1, 5, 4], [1, 2, 5], [4, 3, 1], [3, 7, 1], [1, 7, 2]]

_SURF2_VERTICES = [
    [0.1, 0.1, 0.5], [0.1, 0.9, 0.3], [0.65, 0.82, 0.45], [0.7, 0.3, 0.55],
    [0.3, 0.05, 0.4], [0.85, 0.15, 0.35], [0.5, 0.55, 1], [0.6, 0.7, 1],
    [0.08, 0.48, 0.42], [0.48, 0.08, 0.38], [0.25, 0.75, 0.9], [0, 0, 0],
    [0, 1, 0], [1, 1, 0], [1, 0, 0],
]  # fmt: skip
_SURF2_FACES_1BASED = [
    [9, 13, 12], [14, 13, 3], [11, 9, 7], [7, 10, 4], [12, 15, 5], [15, 10, 5],
    [7, 9, 5], [5, 10, 7], [2, 3, 13], [2, 11, 3], [13, 9, 2], [9, 11, 2],
    [6, 15, 14], [14, 4, 6], [6, 10, 15], [6, 4, 10], [14, 3, 8], [8, 4, 14],
    [7, 4, 8], [8, 11, 7], [3, 11, 8], [1, 9, 12], [12, 5, 1], [1, 5, 9],
]  # fmt: skip

BUILTIN_MESHES: dict[str, tuple[list, list, PaperParameters]] = {
    "surf1": (
        _SURF1_VERTICES,
        _SURF1_FACES_1BASED,
        PaperParameters(0.5, 2.0, 0.16, 0.40, 0.05, 100, 70, 36),
    ),
    "surf2": (
        _SURF2_VERTICES,
        _SURF2_FACES_1BASED,
        PaperParameters(0.5, 2.0, 0.30, 0.25, 0.05, 150, 112, 70),
    ),
}


def is_builtin(name: str) -> bool:
    """True when ``name`` names a built-in mesh (case-insensitive). It means the built-in even where a file
    of that name exists: a mesh file's name ends in its format (``.obj``, ...), so that file could not be
    read as one."""
    return name.lower() in BUILTIN_MESHES


def builtin_mesh(name: str) -> tuple[Mesh, PaperParameters]:
    """The built-in mesh ``name`` (``surf1`` or ``surf2``) and its paper parameters."""
    vertices, faces_1based, params = BUILTIN_MESHES[name.lower()]
    mesh = Mesh(np.array(vertices, dtype=np.float64), np.array(faces_1based) - 1, name=name.lower())
    return mesh, params
