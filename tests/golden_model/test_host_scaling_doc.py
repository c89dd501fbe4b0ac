"""docs/engine.md's "How the host fills the images" (the bundle's memory_image.md) is what `prepare` does.

A host written from that text alone, here in numpy with the formulas as the text states them, must give
`prepare`'s raw values bit for bit: the scale, the nodes, the entries with the fold barrier, the triangles
and the reciprocals, for both dynamics and both orientations of the start.
"""

import math

import numpy as np
import pytest

from golden_model.fixed import FormatSet
from golden_model.fixed.engine import prepare
from golden_model.fixed.format import quantize
from sim.generate import dome_grid
from sim.layouts import initial_layout
from golden_model.params import FlattenParams


def _raw(values, fmt):
    return quantize(np.asarray(values, dtype=np.float64), fmt, "half_up", "saturate")


def _reciprocal(total: int, bits: int) -> tuple[int, int]:
    shift = bits + total.bit_length() - 1
    mantissa = ((1 << (shift + 1)) // total + 1) >> 1  # round half up of 2^shift / T, exactly
    if mantissa == 1 << bits:
        mantissa, shift = mantissa >> 1, shift - 1
    return mantissa, shift


@pytest.mark.parametrize("dynamics", ["momentum", "paper"])
@pytest.mark.parametrize("mirrored", [False, True])
def test_a_host_written_from_the_text_fills_the_images_as_prepare_does(dynamics, mirrored):
    fs = FormatSet.preset("default")
    mesh = dome_grid(6)
    start = initial_layout(mesh, "tutte") * ([-1.0, 1.0] if mirrored else [1.0, 1.0])
    params = FlattenParams(dynamics=dynamics, barrier=dynamics == "momentum", density="auto")
    problem = prepare(mesh, start, params, fs)
    V, F, C = mesh.vertices, mesh.faces, params.spring
    stream, rings = problem.stream, mesh.rings

    # 1. the scale
    edge_length = np.linalg.norm(V[mesh.edges[:, 0]] - V[mesh.edges[:, 1]], axis=1)
    k = -math.floor(math.log2(edge_length.mean()) + 0.5)
    s = 2.0**k
    assert problem.scale_exp == k

    # 2. nodes
    positions = _raw(start * s, fs.position)
    np.testing.assert_array_equal(problem.initial_positions, positions)
    degree = np.diff(stream.indptr)
    area = 0.5 * np.linalg.norm(np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]), axis=1)
    if dynamics == "momentum":
        weight = 2.0 / (C * degree)
        np.testing.assert_array_equal(stream.inv_mass, _raw(weight, fs.inv_mass))
        b = np.zeros(len(V))
        for corner in range(3):
            opposite = V[F[:, (corner + 1) % 3]] - V[F[:, (corner + 2) % 3]]
            np.add.at(b, F[:, corner], params.barrier_gain * C * ((opposite**2).sum(axis=1) / (2 * area)
                                                                  + 2 * params.barrier_threshold) / 4)
        np.testing.assert_array_equal(stream.inv_mass_barrier,
                                      _raw(np.minimum(weight, 4.0 / (C * degree + 2 * b)), fs.inv_mass))
    else:
        mass = np.zeros(len(V))
        np.add.at(mass, F.ravel(), np.repeat(area, 3) / 3)  # rho = 1
        np.testing.assert_array_equal(stream.inv_mass, _raw(1.0 / (mass / mass.min()), fs.inv_mass))

    # 3. entries: the ring (entries k, k+1 span a triangle in the mesh's winding), rest, the barrier
    faces = {tuple(np.roll(f, r)) for f in F.tolist() for r in range(3)}
    owner = np.repeat(np.arange(len(V)), degree)
    successor = np.arange(len(owner)) + 1
    successor[stream.indptr[1:] - 1] = stream.indptr[:-1]
    spans = [(int(owner[e]), int(stream.neighbour[e]), int(stream.neighbour[successor[e]])) in faces
             for e in range(len(owner))]
    assert sum(spans) == 3 * len(F) and all(spans[e] or e == stream.indptr[owner[e] + 1] - 1
                                            for e in range(len(owner)))  # a boundary gap only at a ring's end
    rest = np.linalg.norm(V[owner] - V[stream.neighbour], axis=1) * s
    np.testing.assert_array_equal(stream.rest, _raw(rest, fs.rest_length))
    if dynamics == "momentum":
        u, v = positions[F[:, 1]] - positions[F[:, 0]], positions[F[:, 2]] - positions[F[:, 0]]
        sigma = 1 if (u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0]).sum() >= 0 else -1
        assert sigma == (-1 if mirrored else 1)
        second = stream.neighbour.copy()
        doubled = np.zeros(len(owner))
        for e in np.flatnonzero(spans):
            face = (int(owner[e]), int(stream.neighbour[e]), int(stream.neighbour[successor[e]]))
            carrier = e if sigma == 1 else successor[e]
            second[carrier] = face[2] if sigma == 1 else face[1]
            doubled[carrier] = 2 * area[[tuple(f) in {tuple(np.roll(face, r)) for r in range(3)}
                                         for f in F.tolist()].index(True)] * s * s
        has = doubled > 0
        np.testing.assert_array_equal(stream.barrier.second, second)
        np.testing.assert_array_equal(stream.barrier.threshold,
                                      np.where(has, _raw(params.barrier_threshold * doubled, fs.area), 0))
        np.testing.assert_array_equal(stream.barrier.gain, np.where(
            has, _raw(params.barrier_gain * C / (4 * np.where(has, doubled, 1)), fs.barrier_gain), 0))

    # 4. triangles and 5. the run constants
    np.testing.assert_array_equal(problem.face_areas, _raw(area * s * s, fs.face_area))
    assert problem.half_spring == _raw(C / 2, fs.spring) and problem.damping == _raw(1 - params.damping, fs.damping)
    bits = fs.reciprocal.width
    area_total = int(problem.face_areas.sum())
    length_total = int(stream.rest.sum()) << (fs.error_acc.frac_bits - fs.rest_length.frac_bits)
    assert (problem.area_reciprocal.mantissa, problem.area_reciprocal.shift) == _reciprocal(area_total, bits)
    assert (problem.length_reciprocal.mantissa, problem.length_reciprocal.shift) == _reciprocal(length_total, bits)
