"""Host and controller around the fixed-point pipeline: ``--engine fixed``.

The host maps a mesh into the formats' range and back; the controller runs
Algorithm 1 around :func:`~golden_model.fixed.pipeline.node_update` the way
the hardware-side controller will: E_C from the pipeline's per-node partial
sums, E_S from the triangle areas of the fixed-point layout, both normalised
by precomputed reciprocals, fed to the exp-LUT step generator and to the
stopping rule.

**Scale.** Positions and rest lengths are multiplied by ``2**k`` (exact in
binary), with ``k`` chosen so that the mean rest length lies in
[1/√2, √2) — the range the presets are designed for.  Forces, accelerations
and velocities then scale by the same factor while masses, ``Δt`` and the
dynamics are unchanged, so the fixed-point trajectory approximates the float
trajectory times ``2**k``.  Areas scale by ``4**k``; both sides of ``E_S``
are formed at that scale.  Results are mapped back by ``2**-k``.

**Controller.** :func:`run_fixed` is Algorithm 1's loop on integers alone: the
stopping rule compares raw E_S and E_C with the tolerances quantised by the host
(:class:`StopRule`), and the relative energy change in integers
(:func:`energy_raw`: ``3·(½C)·Σe² + 2·Σc·h`` over the entries, exact), with
``ε`` quantised to :data:`ENERGY_TOL_FRAC_BITS` fraction bits. Nothing on the
decision path is a float, so a controller in hardware reproduces it bit for bit;
floats only report (``Measurement``).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from fractions import Fraction
from typing import Callable

import numpy as np

from ..guard import energy_floor_fraction
from ..mesh import Mesh, folded_by_area, layout_orientation
from ..modes import Step
from ..params import FlattenParams
from ..reference import node_weights
from ..results import FlattenResult, History, Measurement
from .coarse import CoarseConstants, coarse_constants
from .controller import Controller, Setup
from .format import MAX_PRODUCT_WIDTH, Format, Rounding, SaturationCounter, quantize, to_float
from .formats_set import FormatSet
from .measures import SAT, FixedPointError, Reciprocal, _doubled_areas, energy_frac_bits, energy_raw
from .pipeline import BarrierEntries, NeighbourStream, NodeConstants
from .steplut import DT_MAX, DT_MIN, dt_constant, half_dt_sq, lut_value_float

__all__ = ["FixedProblem", "ScaledMesh", "scale_mesh", "prepare", "presets_holding", "flatten_fixed", "load_formats",
           "energy_to_float", "StopRule", "ENERGY_TOL_FRAC_BITS", "run_fixed", "NO_PENALTY"]

#: Why a fixed-point run refuses the penalty (the first words of every such refusal).
NO_PENALTY = "the penalty is not part of the fixed-point pipeline"

HOST_ROUNDING = Rounding.HALF_UP  # host-side conversions of constants and inputs

#: The initial layout must fit in this fraction of the position range (the
#: layout may grow while it relaxes).
POSITION_HEADROOM = 0.5


def load_formats(spec: str) -> FormatSet:
    """A preset name or a JSON file, with errors turned into one-line messages."""
    try:
        return FormatSet.load(spec)
    except FileNotFoundError:
        raise FixedPointError(f"formats file '{spec}' not found (presets: {', '.join(FormatSet.presets())})") from None
    except UnicodeDecodeError:
        raise FixedPointError(f"formats '{spec}': not a JSON file (not text)") from None
    except json.JSONDecodeError as exc:
        raise FixedPointError(f"formats '{spec}': not a JSON file ({exc.msg.lower()} at line {exc.lineno}, column "
                              f"{exc.colno})") from None
    except (ValueError, KeyError, TypeError) as exc:
        raise FixedPointError(f"formats '{spec}': {str(exc).splitlines()[0]}") from None


@dataclass(frozen=True, eq=False)
class FixedProblem:
    """Everything the host precomputes for one mesh, layout and format set."""

    fs: FormatSet
    mesh: Mesh
    params: FlattenParams
    scale_exp: int
    stream: NeighbourStream
    half_spring: int
    damping: int
    face_areas: np.ndarray  # (F,) raw [face_area], scaled by 4**k
    area_reciprocal: Reciprocal
    length_reciprocal: Reciprocal
    orientation: np.ndarray  # (F,) ±1 of the fixed-point P0
    initial_positions: np.ndarray  # (V, 2) raw [position]
    density: float
    winding: float = 1.0  # σ of the fixed-point P0 (the barrier's orientation)
    coarse: CoarseConstants | None = None  # the coarse space's run constants (params.coarse_degree > 0)

    @property
    def momentum(self) -> bool:
        return self.params.mode.step is Step.MOMENTUM

    @property
    def scale(self) -> float:
        return 2.0**self.scale_exp

    def to_float_positions(self, raw: np.ndarray) -> np.ndarray:
        return np.ldexp(to_float(raw, self.fs.position), -self.scale_exp)

    def to_float_velocities(self, raw: np.ndarray) -> np.ndarray:
        return np.ldexp(to_float(raw, self.fs.velocity), -self.scale_exp)

    def constants(self, dt: int) -> NodeConstants:
        """The datapath inputs for a step ``dt`` (raw [dt]; the momentum dynamics: ``β``, and ``½Δt²`` unused)."""
        if self.momentum:
            return NodeConstants(dt, 0, self.half_spring, 1 << self.fs.damping.frac_bits)
        return NodeConstants(dt, int(half_dt_sq(np.int64(dt), self.fs)), self.half_spring, self.damping)


#: Fraction bits of the host-quantised relative-energy tolerance ε (u0.40: ε down to ~1e-12).
ENERGY_TOL_FRAC_BITS = 40


def energy_to_float(problem: "FixedProblem", raw: int) -> float:
    """:func:`energy_raw` in mesh units (float64, for reporting)."""
    return math.ldexp(raw / 3, -energy_frac_bits(problem.fs) - 2 * problem.scale_exp)


def tol_energy_raw(tol_energy: float) -> int:
    """``ε`` as the stop rule holds it: ``ENERGY_TOL_FRAC_BITS`` fraction bits, rounded half up, exactly (``1e300``
    is a tolerance too, not a float overflow)."""
    return math.floor(Fraction(tol_energy) * 2**ENERGY_TOL_FRAC_BITS + Fraction(1, 2))


@dataclass(frozen=True)
class StopRule:
    """Algorithm 1's stopping rule in integers: ``E_S ≤ φ_S``, ``E_C ≤ φ_C`` (raw [error]) and
    ``|E_k − E_k−W| ≤ ε·E_k−W`` with ``ε`` raw at :data:`ENERGY_TOL_FRAC_BITS` fraction bits, or
    ``E_k < floor`` in :func:`energy_raw` units (0 for the paper dynamics; see
    :func:`golden_model.reference.energy_floor`)."""

    area: int
    shape: int
    energy: int
    floor: int = 0

    @classmethod
    def of(cls, params: FlattenParams, fs: FormatSet, floor: int = 0) -> "StopRule":
        """The host's quantisation: ``φ`` floored to the error lsb (a raw error passes exactly when
        its value does; a ``φ`` past error's maximum, which no error exceeds, as that maximum), ``ε`` rounded
        half up (exactly: ``1e300`` is a tolerance too, not a float overflow)."""
        lsb = fs.error.frac_bits
        area, shape = (math.floor(math.ldexp(min(tol, fs.error.max), lsb)) for tol in (params.tol_area, params.tol_shape))
        return cls(area, shape, tol_energy_raw(params.tol_energy), floor)

    def converged(self, energy_before: int, energy_after: int, errors: tuple[int, int]) -> bool:
        if energy_before == 0:
            change_ok = energy_after == 0
        else:
            change_ok = abs(energy_after - energy_before) << ENERGY_TOL_FRAC_BITS <= self.energy * energy_before
        return errors[0] <= self.area and errors[1] <= self.shape and (change_ok or energy_after < self.floor)


def energy_floor_raw(problem: "FixedProblem") -> int:
    """:func:`golden_model.reference.energy_floor` in :func:`energy_raw` units: ``energy_floor_fraction(ε)``
    times the exact energy of every edge at twice its rest length (``½C·Σd²`` over the entries), floored; 0
    where the float model has no floor."""
    if not (problem.params.guard and problem.params.tol_energy > 0):
        return 0
    rest = problem.stream.rest
    reference = energy_raw(problem.fs, problem.half_spring, int(np.sum(rest * rest, dtype=object)), 0)
    return math.floor(energy_floor_fraction(problem.params.tol_energy) * reference)


def _quantize_checked(x: np.ndarray | float, fmt: Format, what: str, fs: FormatSet, hint: str) -> np.ndarray:
    raw = quantize(x, fmt, HOST_ROUNDING, SAT)
    worst = float(np.max(np.abs(x)))
    if worst > fmt.max or (np.ndim(x) and np.any(np.abs(x) > fmt.max)):
        raise FixedPointError(f"{what} {worst:.6g} does not fit format set '{fs.name}' "
                              f"({fmt}: max {fmt.max:.6g}); {hint}")
    return raw


def _refuse_zeros(raw: np.ndarray, value: np.ndarray, what: str, field: str, fs: FormatSet) -> None:
    """Refuse, naming the field, when a positive quantity the host rounded (``value``, scaled units) became 0."""
    zero = (np.asarray(raw) == 0) & (np.asarray(value) > 0)
    if zero.any():
        fmt = getattr(fs, field)
        smallest = float(np.min(np.asarray(value)[zero]))
        raise FixedPointError(f"{what} of {smallest:.3g} (scaled units) rounds to 0 in {field} {fmt} of format set "
                              f"'{fs.name}' (lsb {fmt.lsb:.3g}); choose a format set with more fraction bits for it")


@dataclass(frozen=True, eq=False)
class ScaledMesh:
    """What :func:`prepare` takes from the mesh and the parameters alone, scaled into a format set: every
    refusal that no layout can avoid comes from building it."""

    scale_exp: int
    rest: np.ndarray  # (E,) raw [rest_length], per edge
    inv_mass: np.ndarray  # (V,) raw [inv_mass]
    inv_mass_barrier: np.ndarray | None  # (V,) raw [inv_mass], the barrier's weights (momentum with barrier)
    half_spring: int
    damping: int
    face_areas: np.ndarray  # (F,) raw [face_area], scaled by 4**k
    density: float

    @property
    def scale(self) -> float:
        return 2.0**self.scale_exp


def scale_mesh(mesh: Mesh, params: FlattenParams, fs: FormatSet) -> ScaledMesh:
    """The mesh's constants in ``fs`` (positions scaled by ``2**k`` so that the mean edge is about 1).

    Raises :class:`FixedPointError` with one line naming the first quantity that does not fit, whatever
    the initial layout: callers refuse such a mesh before computing a layout (:func:`prepare` checks the
    layout's own extent after this)."""
    check_fixed_params(params, fs)
    rest = mesh.rest_lengths
    k = -int(math.floor(math.log2(float(rest.mean())) + 0.5))
    scale = 2.0**k

    degree = int(np.diff(mesh.neighbours[0]).max())
    if degree > fs.max_degree:
        raise FixedPointError(f"a node has {degree} neighbours; format set '{fs.name}' accumulates at most "
                              f"{fs.max_degree} (max_degree)")
    scaled_rest = rest * scale
    longest = float(scaled_rest.max())
    if longest >= fs.delta.max or longest >= fs.rest_length.max:
        raise FixedPointError(f"the longest edge is {longest:.4g} mean edge lengths; format set '{fs.name}' "
                              f"holds edges below {min(fs.delta.max, fs.rest_length.max):.4g}: "
                              "the mesh's edge lengths vary too much for these formats")
    shortest = float(scaled_rest.min())
    if shortest <= 1.0 / fs.rsqrt.max:
        raise FixedPointError(f"the shortest edge is {shortest:.3g} mean edge lengths; the rsqrt format "
                              f"{fs.rsqrt} of '{fs.name}' needs edges above {1.0 / fs.rsqrt.max:.3g}: "
                              "the mesh's edge lengths vary too much for these formats")
    rest_raw = quantize(scaled_rest, fs.rest_length, HOST_ROUNDING, SAT)
    _refuse_zeros(rest_raw, scaled_rest, "an edge's rest length", "rest_length", fs)
    model_density = mesh.auto_density() if params.density == "auto" else float(params.density)
    inv_mass_barrier_raw = None
    if params.mode.step is Step.MOMENTUM:
        inv_mass = node_weights(mesh, params.spring)
        inv_mass_raw = _quantize_checked(inv_mass, fs.inv_mass, "the weight 2/(C deg)", fs,
                                         "use a larger --spring, or a wider inv_mass format")
        if params.barrier:  # the smaller weight of a node while its barrier is active
            inv_mass = node_weights(mesh, params.spring, (params.barrier_threshold, params.barrier_gain))
            inv_mass_barrier_raw = _quantize_checked(inv_mass, fs.inv_mass, "the barrier weight w_i", fs,
                                                     "use a larger --spring, or a wider inv_mass format")
    else:
        with np.errstate(over="ignore", divide="ignore"):  # masses below 1/float's maximum (or 0 in float):
            inv_mass = 1.0 / mesh.masses(model_density)  # an infinite 1/m, refused below
        inv_mass_raw = _quantize_checked(inv_mass, fs.inv_mass, "1/m", fs,
                                         "use --density auto (or a larger density), or a wider inv_mass format")
    if min(w.min() for w in (inv_mass_raw, inv_mass_barrier_raw) if w is not None) < 16:
        if not params.mode.has_masses:
            raise FixedPointError(f"the weight w_i down to {inv_mass.min():.3g} keeps fewer than 5 bits in "
                                  f"{fs.inv_mass} of format set '{fs.name}': use a smaller --spring, or a wider "
                                  "inv_mass format")
        raise FixedPointError(f"1/m down to {inv_mass.min():.3g} keeps fewer than 5 bits in {fs.inv_mass} "
                              f"of format set '{fs.name}': the node masses vary too much (lower the density)")
    half_spring = int(_quantize_checked(0.5 * params.spring, fs.spring, "C/2", fs, "use a smaller --spring"))
    damping = int(quantize(1.0 - params.damping, fs.damping, HOST_ROUNDING, SAT))
    if params.barrier:  # its thresholds and gains do not depend on which corner's entry carries them
        _barrier_entries(mesh, params, fs, scale, 1.0)
    if mesh.n_faces >= 1 << (MAX_PRODUCT_WIDTH - fs.face_area.width):  # Σ|A − |A'|| must fit int64
        raise FixedPointError(f"the mesh has {mesh.n_faces} triangles; the area sum of format set '{fs.name}' "
                              f"takes fewer than 2^{MAX_PRODUCT_WIDTH - fs.face_area.width} ({fs.face_area})")
    face_areas = _quantize_checked(mesh.face_areas * scale * scale, fs.face_area, "a triangle's area", fs,
                                   "the mesh's triangles vary too much in size for these formats")
    _refuse_zeros(face_areas, mesh.face_areas * scale * scale, "a triangle's area", "face_area", fs)
    return ScaledMesh(k, rest_raw, inv_mass_raw, inv_mass_barrier_raw, half_spring, damping, face_areas,
                      model_density)


def prepare(mesh: Mesh, initial_positions: np.ndarray, params: FlattenParams, fs: FormatSet) -> FixedProblem:
    """Scale the problem into ``fs`` and precompute the controller's constants.

    Raises :class:`FixedPointError` with one line naming the first quantity
    that does not fit: the mesh's (:func:`scale_mesh`), then the layout's.
    """
    scaled = scale_mesh(mesh, params, fs)
    p0 = np.asarray(initial_positions, dtype=np.float64) * scaled.scale
    extent = float(np.max(np.abs(p0)))
    if extent > POSITION_HEADROOM * fs.position.max:
        raise FixedPointError(
            f"the initial layout spans ±{extent:.4g} mean edge lengths; format set '{fs.name}' holds positions "
            f"up to ±{fs.position.max:.4g} ({fs.position}) with room to grow up to ±{POSITION_HEADROOM * fs.position.max:.4g}: "
            f"the mesh has too many edges across for these formats; choose a format set with more integer bits")
    positions = quantize(p0, fs.position, HOST_ROUNDING, SAT)

    rings = mesh.rings  # the stream's order: a node's triangles are consecutive entries
    winding = layout_orientation(positions.astype(np.float64), mesh.faces)
    barrier = _barrier_entries(mesh, params, fs, scaled.scale, winding) if params.barrier else None
    stream = NeighbourStream(rings.indptr, rings.neighbour, scaled.rest[rings.edge_id], scaled.inv_mass, barrier,
                             scaled.inv_mass_barrier)
    area_total = int(scaled.face_areas.sum())  # [face_area], exact
    length_total = int(stream.rest.sum()) << (fs.error_acc.frac_bits - fs.rest_length.frac_bits)  # [error_acc]
    orientation = np.where(_doubled_areas(fs, positions, mesh.faces) >= 0, 1, -1)
    mantissa_bits = fs.reciprocal.width
    coarse = (coarse_constants(positions, mesh.edges, params.spring, params.coarse_degree)
              if params.coarse_degree else None)
    return FixedProblem(fs, mesh, params, scaled.scale_exp, stream, scaled.half_spring, scaled.damping,
                        scaled.face_areas, Reciprocal.of(area_total, mantissa_bits),
                        Reciprocal.of(length_total, mantissa_bits), orientation, positions, scaled.density, winding,
                        coarse)


def _barrier_entries(mesh: Mesh, params: FlattenParams, fs: FormatSet, scale: float,
                     winding: float) -> BarrierEntries:
    """Each triangle on one entry of each of its corners, wound so that ``X > 0`` when unfolded.

    Ring entry ``k`` of node ``i`` and its successor span the triangle
    ``(i, j_k, j_k+1)`` in the mesh's winding.  With ``σ = +1`` entry ``k``
    carries it (``second = j_k+1``); with ``σ = −1`` entry ``k+1`` does
    (``second = j_k``), which negates ``X`` and ``D`` as the barrier's ``σ`` does.
    """
    rings = mesh.rings
    n = len(rings.neighbour)
    owner = np.repeat(np.arange(mesh.n_vertices), np.diff(rings.indptr))
    face = rings.face.copy()
    second = rings.next_neighbour.copy()
    if winding < 0:
        # entry k+1 (cyclically within the node) takes entry k's triangle
        successor = np.arange(n) + 1
        last = rings.indptr[1:] - 1
        successor[last] = rings.indptr[:-1]
        face_moved = np.full(n, -1, dtype=np.int64)
        second_moved = owner.copy()
        face_moved[successor] = face
        second_moved[successor] = rings.neighbour
        face, second = face_moved, second_moved
    has = face >= 0
    doubled = 2.0 * mesh.face_areas[np.where(has, face, 0)] * scale * scale
    threshold = np.where(has, params.barrier_threshold * doubled, 0.0)
    gain = np.where(has, params.barrier_gain * params.spring / (4.0 * doubled), 0.0)
    hint = "the mesh's triangles vary too much in size for these formats (or lower --barrier-gain)"
    threshold_raw = _quantize_checked(threshold, fs.area, "a barrier threshold", fs, hint)
    gain_raw = _quantize_checked(gain, fs.barrier_gain, "the barrier gain mu C/(4 X*)", fs, hint)
    _refuse_zeros(threshold_raw[has], threshold[has], "a barrier threshold kappa X*", "area", fs)
    _refuse_zeros(gain_raw[has], gain[has], "the barrier gain mu C/(4 X*)", "barrier_gain", fs)
    return BarrierEntries(np.where(has, second, rings.neighbour), threshold_raw, gain_raw)


def folded_count(problem: FixedProblem, positions: np.ndarray) -> int:
    """Faces whose exact orientation disagrees with the whole pattern's (the honest fold count).

    Exact for every triangle whose edges fit ``face_edge``; a longer edge saturates (counted
    by :func:`area_sum` on the same positions), and that triangle's sign may then be wrong.
    """
    return int(np.count_nonzero(folded_by_area(_doubled_areas(problem.fs, positions, problem.mesh.faces))))


def flipped_count(problem: FixedProblem, positions: np.ndarray) -> int:
    """Faces whose exact orientation is opposite to the fixed-point ``P0``'s (as :func:`folded_count`)."""
    return int(np.sum(problem.orientation * _doubled_areas(problem.fs, positions, problem.mesh.faces) < 0))


class FixedEngine(Controller):
    """``--engine fixed``: the engine's :class:`~golden_model.fixed.controller.Controller` on the host's
    :class:`FixedProblem`, with the measurements a run reports (``positions``/``velocities`` mapped back
    to mesh units, float64; ``raw_positions``/``raw_velocities`` are the bit-exact state).

    The single-pass datapath measures a layout with a pass at ``Δt = 0``, ``1 − γ = 1`` (which moves
    nothing) before the real pass: the partial sums do not depend on the step, so both passes
    produce the same terms.
    """

    def __init__(self, problem: FixedProblem, counter: SaturationCounter):
        super().__init__(controller_setup(problem), problem.initial_positions.copy(),
                         np.zeros_like(problem.initial_positions), counter)
        self.problem = problem

    @property
    def positions(self) -> np.ndarray:
        return self.problem.to_float_positions(self.raw_positions)

    @property
    def velocities(self) -> np.ndarray:
        return self.problem.to_float_velocities(self.raw_velocities)

    def measure(self) -> Measurement:
        """The passes of the current layout (once per layout) and what they report, in mesh units."""
        super().measure()
        p, fs = self.problem, self.problem.fs
        return Measurement(float(to_float(self.errors[0], fs.error)), float(to_float(self.errors[1], fs.error)),
                           energy_to_float(p, self.energy_raw), flipped_count(p, self.raw_positions),
                           folded_count(p, self.raw_positions))

    def step_size(self, _: Measurement) -> float:
        """:meth:`choose_step`, as the float step (1 with momentum: β goes into the Δt port)."""
        dt = self.choose_step()
        return 1.0 if self.setup.mode.step is Step.MOMENTUM else float(to_float(dt, self.problem.fs.dt))

    def advance(self, dt: float = 0.0) -> None:
        super().advance()


def controller_setup(problem: FixedProblem) -> Setup:
    """The controller's view of the host's problem."""
    fs, params = problem.fs, problem.params
    mode = params.mode
    dt = int(quantize(params.dt, fs.dt, HOST_ROUNDING, SAT)) if mode.step is Step.FIXED else 0
    return Setup(fs, mode, problem.stream, problem.mesh.faces, problem.face_areas, problem.half_spring,
                 problem.damping, dt, problem.area_reciprocal, problem.length_reciprocal,
                 StopRule.of(params, fs, energy_floor_raw(problem)), params.max_iter, params.energy_window,
                 winding=int(problem.winding), coarse=problem.coarse)


def _fits(what: str, value: float, field: str, fs: FormatSet, hint: str = "") -> int:
    """``value`` > 0 rounded into ``fs.<field>`` by the host; refused, naming the field, when it rounds to 0
    or does not fit (would saturate)."""
    fmt = getattr(fs, field)
    raw = int(quantize(value, fmt, HOST_ROUNDING, SAT))
    if value > fmt.max or raw == 0:
        problem = f"rounds to 0 (lsb {fmt.lsb:.3g})" if raw == 0 else f"does not fit (max {fmt.max:.6g})"
        raise FixedPointError(f"{what} {value:.6g} {problem} in {field} {fmt} of format set '{fs.name}'"
                              + (f"; {hint}" if hint else ""))
    return raw


def check_fixed_params(params: FlattenParams, fs: FormatSet) -> None:
    """Refuse parameters the formats cannot represent faithfully, and modes the fixed-point model does not
    have, before any mesh work (:func:`prepare` checks the mesh against the formats): every constant the
    host rounds into a format (``Δt`` or the step generator's range, ``β``, ``C/2``, ``1 − γ``, the
    tolerances) must neither round to 0 nor saturate; each refusal is one line naming the field."""
    if params.update != "jacobi":
        raise FixedPointError("the fixed-point engine computes the jacobi order (as the hardware does); "
                              "use --update jacobi")
    if params.penalty:
        raise FixedPointError(f"{NO_PENALTY}; drop --penalty")
    if params.mode.step is Step.MOMENTUM and fs.velocity.frac_bits != fs.position.frac_bits:
        raise FixedPointError(f"the momentum dynamics adds V to P directly: format set '{fs.name}' needs velocity "
                              f"({fs.velocity}) and position ({fs.position}) with the same fraction bits")
    if params.guard and fs.face_edge.frac_bits != fs.position.frac_bits:
        raise FixedPointError(f"the step guard's certificate is exact only with face_edge ({fs.face_edge}) at "
                              f"position's ({fs.position}) fraction bits: format set '{fs.name}'")
    if 0 < params.tol_energy < math.ldexp(1, -ENERGY_TOL_FRAC_BITS - 1):
        raise FixedPointError(f"--tol-energy {params.tol_energy:g} is below the controller's resolution "
                              f"2^-{ENERGY_TOL_FRAC_BITS} ({math.ldexp(1, -ENERGY_TOL_FRAC_BITS):.3g}); use 0 or a larger value")
    finer = "choose a format set with more fraction bits for it"
    if params.mode.step is Step.MOMENTUM:  # β_k = k/(k+3) goes into the Δt port: its first non-zero value
        _fits("the momentum factor beta_1", 0.25, "dt", fs, finer)
    elif params.mode.step is Step.FIXED:
        if params.dt > fs.dt.max or float(quantize(params.dt, fs.dt, HOST_ROUNDING, SAT)) == 0:
            raise FixedPointError(f"dt {params.dt} does not fit format set '{fs.name}' ({fs.dt}: "
                                  f"{fs.dt.lsb:.3g} .. {fs.dt.max:.6g})")
        if int(half_dt_sq(np.int64(_fits("dt", params.dt, "dt", fs)), fs)) == 0:
            raise FixedPointError(f"dt^2/2 for dt {params.dt:g} rounds to 0 in half_dt_sq {fs.half_dt_sq} of format "
                                  f"set '{fs.name}' (lsb {fs.half_dt_sq.lsb:.3g}); {finer}")
    else:  # the step generator: Δt from DT_MIN (E = 0) to DT_MAX (E = 1)
        _fits("the step generator's smallest dt", DT_MIN, "dt", fs, finer)
        _fits("the step generator's largest dt", DT_MAX, "dt", fs, "choose a dt format with a larger range")
        _fits("the exp table's smallest entry", float(lut_value_float(0.0)), "lut_entry", fs, finer)
        if int(half_dt_sq(np.int64(dt_constant(fs.dt)), fs)) == 0:
            raise FixedPointError(f"dt^2/2 for the step generator's smallest dt {DT_MIN:g} rounds to 0 in half_dt_sq "
                                  f"{fs.half_dt_sq} of format set '{fs.name}' (lsb {fs.half_dt_sq.lsb:.3g}); {finer}")
    if params.spring > 0:
        _fits("C/2", 0.5 * params.spring, "spring", fs, "use another --spring, or a spring format that holds it")
    if params.damping < 1:
        factor = _fits("the velocity factor 1 - damping", 1.0 - params.damping, "damping", fs, finer)
        if params.damping > 0 and factor == 1 << fs.damping.frac_bits:  # the run would not damp at all
            raise FixedPointError(f"damping {params.damping:g} rounds to 0: 1 - damping is 1 in damping {fs.damping} "
                                  f"of format set '{fs.name}' (lsb {fs.damping.lsb:.3g}); use a larger --damping, "
                                  "or none, or a damping format with more fraction bits")
    for option, tolerance in (("--tol-area", params.tol_area), ("--tol-shape", params.tol_shape)):
        if 0 < tolerance < 1 and math.floor(math.ldexp(tolerance, fs.error.frac_bits)) == 0:
            raise FixedPointError(f"{option} {tolerance:g} rounds to 0 in error {fs.error} of format set '{fs.name}' "
                                  f"(lsb {fs.error.lsb:.3g}): the rule could never hold; use a larger tolerance, "
                                  "or an error format with more fraction bits")


def presets_holding(mesh: Mesh, initial_positions: np.ndarray | None, params: FlattenParams) -> list[str]:
    """The preset format sets (:meth:`FormatSet.presets`) that hold this problem: those :func:`prepare`
    scales it into without a :class:`FixedPointError` (with ``initial_positions`` ``None``: those that hold
    the mesh, :func:`scale_mesh`)."""
    holding = []
    for name in FormatSet.presets():
        try:
            if initial_positions is None:
                scale_mesh(mesh, params, FormatSet.preset(name))
            else:
                prepare(mesh, initial_positions, params, FormatSet.preset(name))
        except FixedPointError:
            continue
        holding.append(name)
    return holding


def flatten_fixed(
    mesh: Mesh,
    initial_positions: np.ndarray,
    params: FlattenParams,
    fs: FormatSet | None = None,
    on_iteration: Callable[[int, Measurement], None] | None = None,
) -> FlattenResult:
    """Algorithm 1 on the bit-exact pipeline; results mapped back to mesh units.

    ``result.extra`` carries ``saturations`` (total events), ``saturation_events``
    (per signal), ``formats`` and ``scale``.
    """
    fs = FormatSet.preset("default") if fs is None else fs
    check_fixed_params(params, fs)
    problem = prepare(mesh, initial_positions, params, fs)
    counter = SaturationCounter()
    engine = FixedEngine(problem, counter)
    result = run_fixed(engine, on_iteration)
    result.extra.update({
        "formats": fs.name,
        "scale": problem.scale,
        "saturations": counter.total,
        "saturation_events": {k: v for k, v in counter.saturations.items() if v},
    })
    result.engine_state = engine  # the raw state, for bit-level comparisons
    return result


def run_fixed(engine: FixedEngine, on_iteration: Callable[[int, Measurement], None] | None = None) -> FlattenResult:
    """Algorithm 1's loop (:meth:`Controller.run`), every decision on raw integers; never diverges (the
    formats saturate, and ``result.extra`` counts it). Each iteration is recorded in the history."""
    problem = engine.problem
    history = History()
    history.append(math.nan, engine.measure(), accepted=None)  # (the start: no step)

    def record(k: int) -> None:
        measurement = engine.measure()
        dt = 1.0 if engine.setup.mode.step is Step.MOMENTUM else float(to_float(engine.dt, problem.fs.dt))
        history.append(dt, measurement, engine.accepted)
        if on_iteration is not None:
            on_iteration(k, measurement)

    status, k = engine.run(record)
    extra = engine.guard.summary() if engine.guard is not None else {}
    return FlattenResult(engine.positions, engine.velocities, problem.to_float_positions(problem.initial_positions),
                         history, status, k, problem.params, problem.density, engine="fixed", extra=extra)
