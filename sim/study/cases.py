"""The cases of a study built from mesh names: built-in, generated and file meshes, each with its start
layouts (the model's :class:`~golden_model.study.StudyCase` holds one)."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Sequence

from golden_model.builtin import builtin_mesh, is_builtin
from golden_model.mesh import Mesh
from golden_model.params import FlattenParams, ParameterError
from golden_model.study import GENERATED_PARAMS, StudyCase

from ..generate import GENERATED_MESHES
from ..layouts import initial_layout
from ..mesh_io import load_mesh

#: The generated meshes a study takes by name.
GENERATED_MESH_NAMES = tuple(GENERATED_MESHES)
#: The default meshes of a study.
STUDY_MESHES = ("surf1", "surf2") + GENERATED_MESH_NAMES


def resolve_study_mesh(name: str) -> tuple[str, Mesh, FlattenParams]:
    """``(display name, mesh, default parameters)`` for a built-in, generated or file mesh.

    Built-ins take their paper parameter sets (jacobi, no damping); generated
    and file meshes take :data:`GENERATED_PARAMS`.
    """
    path = Path(name)
    if is_builtin(name):
        mesh, paper = builtin_mesh(name)
        return name.lower(), mesh, paper.flatten_params()
    if name.lower() in GENERATED_MESH_NAMES:  # (a file of that name has no mesh format's ending)
        return name.lower(), GENERATED_MESHES[name.lower()](), GENERATED_PARAMS
    if os.path.lexists(path) or path.suffix or len(path.parts) > 1:
        return path.stem, load_mesh(path), GENERATED_PARAMS  # (what is wrong with a path: load_mesh says it)
    raise ParameterError(f"unknown mesh '{name}': expected one of {', '.join(STUDY_MESHES)} or a mesh file")


def build_cases(meshes: Sequence[str] = STUDY_MESHES, inits: Sequence[str] = ("pca", "tutte"),
                steps: Sequence[str] = ("fixed", "variable"), max_iter: int | None = None) -> list[StudyCase]:
    """Every combination mesh × init × step (meshes in the given order, duplicates dropped)."""
    if not meshes:
        raise ParameterError("no meshes to study")
    for init in inits:
        if init not in ("pca", "tutte"):
            raise ParameterError(f"unknown initial layout '{init}': expected pca or tutte")
    cases: list[StudyCase] = []
    seen: set[str] = set()
    for spec in meshes:
        label, mesh, params = resolve_study_mesh(spec)
        if label in seen:
            if spec.lower() in seen:
                continue  # the same mesh twice
            k = 2
            while f"{label}-{k}" in seen:
                k += 1
            label = f"{label}-{k}"
        seen.add(label)
        if max_iter is not None:
            params = params.with_(max_iter=max_iter)
        for init in inits:
            p0 = initial_layout(mesh, init)
            for step in steps:
                cases.append(StudyCase(f"{label}/{init}/{step}", label, mesh, init, p0, params.with_(step=step)))
    return cases
