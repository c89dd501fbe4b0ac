"""How much a pattern distorts its mesh: per-triangle area ratio, per-edge strain, and the worst 1 %.

* area ratio of triangle t: ``|A'_t| / A_t`` (2D over 3D area; 1 = no change, folded triangles marked);
* strain of edge e: ``l_e / d_e - 1`` (engineering strain: flat length over 3D length, minus 1; > 0 stretched).

:func:`write_distortion_csv` writes both as one table (``element`` = ``face`` or ``edge``);
:func:`worst_summary` is what ``springflat flatten --json`` reports under ``distortion``.
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from golden_model.mesh import Mesh, folded_faces, signed_areas_2d

from .outputs import atomic_write

#: The share of faces and edges :func:`worst_summary` calls the worst.
WORST_FRACTION = 0.01
DISTORTION_HEADER = ("element", "index", "v0", "v1", "v2", "unit", "size_3d", "size_2d", "ratio", "strain",
                     "folded")


@dataclass(frozen=True)
class Distortion:
    """Per-face and per-edge distortion of a layout.

    Attributes:
        faces: ``(F, 3)`` vertex indices; ``edges``: ``(E, 2)``.
        area_3d, area_2d: ``(F,)`` triangle areas, units²; ``area_2d`` unsigned.
        area_ratio: ``(F,)`` ``area_2d / area_3d``.
        folded: ``(F,)`` bool, :func:`golden_model.mesh.folded_faces`.
        length_3d, length_2d: ``(E,)`` edge lengths, units.
        strain: ``(E,)`` ``length_2d / length_3d - 1``.
    """

    faces: np.ndarray
    edges: np.ndarray
    area_3d: np.ndarray
    area_2d: np.ndarray
    area_ratio: np.ndarray
    folded: np.ndarray
    length_3d: np.ndarray
    length_2d: np.ndarray
    strain: np.ndarray


def distortion(mesh: Mesh, layout: np.ndarray) -> Distortion:
    """The distortion of ``layout`` (``(V, 2)``) against ``mesh``."""
    layout = np.asarray(layout, dtype=np.float64)
    area_2d = np.abs(signed_areas_2d(layout, mesh.faces))
    i, j = mesh.edges.T
    length_2d = np.linalg.norm(layout[j] - layout[i], axis=1)
    return Distortion(mesh.faces, mesh.edges, mesh.face_areas, area_2d, area_2d / mesh.face_areas,
                      folded_faces(layout, mesh.faces), mesh.rest_lengths, length_2d,
                      length_2d / mesh.rest_lengths - 1.0)


def _worst(deviation: np.ndarray, fraction: float) -> tuple[np.ndarray, float]:
    """The indices of the ``ceil(fraction * N)`` largest ``deviation`` (worst first), and the smallest of them."""
    count = max(1, math.ceil(fraction * len(deviation) - 1e-9))
    order = np.argsort(-deviation, kind="stable")[:count]
    return order, float(deviation[order[-1]])


def worst_summary(d: Distortion, fraction: float = WORST_FRACTION) -> dict:
    """The worst ``fraction`` of faces (by ``|log area_ratio|``) and of edges (by ``|strain|``).

    ``area_ratio.worst_band`` is ``[1/r, r]``: every face outside the worst share has its ratio inside it
    (``r = exp`` of the smallest ``|log ratio|`` among the worst); ``edge_strain.worst_abs`` likewise bounds
    ``|strain|`` of every other edge.  ``worst_count`` is ``ceil(fraction * N)``.
    """
    with np.errstate(divide="ignore"):  # a triangle flattened to a line: |log 0| = inf, the worst
        log_ratio = np.abs(np.log(d.area_ratio))
    faces, face_edge = _worst(log_ratio, fraction)
    edges, edge_edge = _worst(np.abs(d.strain), fraction)
    r = math.exp(face_edge)
    return {
        "fraction": fraction,
        "faces": len(d.area_ratio),
        "edges": len(d.strain),
        "folded": int(d.folded.sum()),
        "area_ratio": {
            "min": float(d.area_ratio.min()), "median": float(np.median(d.area_ratio)),
            "max": float(d.area_ratio.max()),
            "worst_count": len(faces), "worst_band": [1.0 / r, r],
            "worst_mean": float(d.area_ratio[faces].mean()),
            "worst_face": int(faces[0]), "worst_value": float(d.area_ratio[faces[0]]),
        },
        "edge_strain": {
            "min": float(d.strain.min()), "median": float(np.median(d.strain)), "max": float(d.strain.max()),
            "worst_count": len(edges), "worst_abs": edge_edge,
            "worst_mean_abs": float(np.abs(d.strain[edges]).mean()),
            "worst_edge": [int(v) for v in d.edges[edges[0]]], "worst_value": float(d.strain[edges[0]]),
        },
    }


def write_distortion_csv(path: Path, d: Distortion, units: str = "mm") -> None:
    """CSV of :data:`DISTORTION_HEADER`: one row per face, then one per edge.

    ``face`` rows: ``v0 v1 v2``, ``unit`` = ``<units>^2``, ``size_3d``/``size_2d`` the areas, ``ratio`` the
    area ratio, ``strain`` = ratio - 1 (areal strain), ``folded`` 0/1.  ``edge`` rows: ``v0 v1`` (``v2``
    empty), ``unit`` = ``<units>``, the lengths, ``ratio`` = l/d, ``strain`` = l/d - 1, ``folded`` empty.
    Numbers are written with ``repr`` (they read back exactly).
    """
    with atomic_write(path) as tmp, open(tmp, "w", newline="", encoding="utf-8") as out:
        writer = csv.writer(out)
        writer.writerow(DISTORTION_HEADER)
        area_unit = f"{units}^2"
        for t, ((a, b, c), a3, a2, ratio, folded) in enumerate(zip(d.faces.tolist(), d.area_3d.tolist(),
                                                                   d.area_2d.tolist(), d.area_ratio.tolist(),
                                                                   d.folded.tolist())):
            writer.writerow(("face", t, a, b, c, area_unit, repr(a3), repr(a2), repr(ratio), repr(ratio - 1.0),
                             int(folded)))
        for e, ((a, b), l3, l2, strain) in enumerate(zip(d.edges.tolist(), d.length_3d.tolist(),
                                                         d.length_2d.tolist(), d.strain.tolist())):
            writer.writerow(("edge", e, a, b, "", units, repr(l3), repr(l2), repr(l2 / l3), repr(strain), ""))
