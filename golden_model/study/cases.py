"""The cases of a study: mesh × initial layout ``P0`` × step mode, with their parameters."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..mesh import Mesh
from ..params import FlattenParams

GENERATED_PARAMS = FlattenParams(density="auto", damping=0.05, tol_area=0.01, tol_shape=0.01, tol_energy=0.05,
                                 max_iter=300)
"""Parameters of generated and file meshes in a study (built-ins use their paper sets)."""


@dataclass(frozen=True, eq=False)
class StudyCase:
    """One flattening problem: a mesh, an initial layout ``P0`` and parameters."""

    name: str  # "<mesh>/<init>/<step>"
    mesh_name: str
    mesh: Mesh
    init: str
    positions: np.ndarray  # P0, (V, 2)
    params: FlattenParams

    @property
    def step(self) -> str:
        return self.params.step

    @property
    def mean_edge(self) -> float:
        return float(self.mesh.rest_lengths.mean())

    @property
    def work(self) -> int:
        """A run-time estimate (entries × iteration budget), for scheduling."""
        return (2 * self.mesh.n_edges + self.mesh.n_vertices) * self.params.max_iter
