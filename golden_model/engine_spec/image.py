"""The engine's memory images and an image-driven model of its controller.

``SpringflatEngine`` (issue 11) runs Algorithm 1 from memories the host loads
over the bus.  This module is the contract of those memories, in one place:

* **Word layouts** (:class:`MemoryLayout`): per memory an ordered field list
  (name, width, signedness, format name) built from a
  :class:`~golden_model.fixed.FormatSet` and an :class:`EngineCapacity`; the
  RTL turns it into a ``lib.data.StructLayout`` in the same order (first field
  at bit 0), and the images are packed with it.  Over the bus a memory word is
  ``ceil(bits/32)`` 32-bit words (word 0 = bits 31:0) at a stride of the next
  power of two, so an address decodes by bit slicing.
* **Run constants** (:func:`run_constant_fields`): the raw integers the
  controller needs besides the memories (counts, ½C, 1 − γ, modes, the fixed
  ``Δt``, both reciprocals, the stop rule's tolerances, ``N_max``).
* **Images** (:func:`build_image`): a :class:`~golden_model.fixed.engine.FixedProblem`
  (the host scaling of :func:`~golden_model.fixed.engine.prepare`) packed into
  the three memories and the constants; vectorised (no loop per vertex).
* **The controller** (:func:`run_image`): Algorithm 1 pass by pass from the
  decoded images, as the engine runs it, on the golden model's own arithmetic
  (``node_terms``, ``area_error``, ``shape_error``, ``energy_raw``, ``StopRule``,
  ``integrate``/``integrate_momentum``, ``node_power``/``power_sum``,
  ``MomentumState``, ``step_size``): bit-identical to
  :func:`~golden_model.fixed.engine.run_fixed`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..coarse import COARSE_DEGREE_MAX, basis_exponents
from ..guard import ENERGY_WINDOW
from ..modes import MODE_CODE_BITS, RUN_MODES, RunMode, Step
from ..fixed.coarse import MATRIX_EXPONENT_BITS, OPERAND_BITS, SUM_BITS, BASIS_FRAC_BITS, CoarseConstants
from ..fixed.controller import Controller, Setup
from ..fixed.engine import (ENERGY_TOL_FRAC_BITS, HOST_ROUNDING, FixedProblem, StopRule, check_fixed_params,
                            energy_floor_raw, tol_energy_raw)
from ..fixed.measures import SAT, FixedPointError, Reciprocal, energy_shifts
from ..fixed.format import Format, SaturationCounter, quantize, raw_range
from ..fixed.formats_set import FormatSet
from ..fixed.pipeline import BarrierEntries, NeighbourStream
from ..mesh import Mesh

__all__ = ["EngineCapacity", "DEFAULT_CAPACITY", "LARGEST_85F_CAPACITY", "WordField", "MemoryLayout", "memory_layouts",
           "node_word_layout", "entry_word_layout", "triangle_word_layout", "basis_field_names", "basis_word_layout",
           "matrix_word_layout", "coarse_constant_fields", "run_constant_fields", "energy_width", "energy_check_width",
           "EngineImage", "build_image", "decode_coarse", "decode_nodes", "decode_entries", "decode_triangles",
           "constant_fault", "EntryCountError", "ImageRunResult", "run_image", "image_energy_window", "BUS_WORD_BITS",
           "ITERATION_BITS", "SATURATION_BITS", "ENERGY_TOL_INT_BITS", "RESULTS", "ENGINE_RUN_MODES", "MODE_FIELDS",
           "image_mode", "LANES", "entry_lanes", "lane_rows", "lane_entry_counts"]

BUS_WORD_BITS = 32
"""Width of one bus word (Wishbone ``dat``)."""

ITERATION_BITS = 32
"""Width of ``max_iter`` and of the iteration counter."""

SATURATION_BITS = 32
"""Width of the saturation-event counter (it stops at its maximum, never wraps) and of its limit."""

ENERGY_TOL_INT_BITS = 8
"""Integer bits of the relative-energy tolerance ε (u8.40 with :data:`ENERGY_TOL_FRAC_BITS`)."""

RESULTS = ("none", "converged", "max-iterations", "diverged", "no-mesh", "bad-constants", "stalled")
"""The run's result codes, in code order (STATUS.result)."""

ENGINE_RUN_MODES: tuple[RunMode, ...] = RUN_MODES
"""The run modes ``SpringflatEngine`` runs: ``MODE.mode`` holds one of their codes; START answers any
other code with ``bad-constants``."""

MODE_FIELDS = ("mode", "barrier")
"""The run constants that share the ``MODE`` register, from bit 0 up."""


LANES = (1, 2, 4)
"""The engine's lane counts K (``EngineCapacity.lanes``)."""


def _next_power_of_two(n: int) -> int:
    return 1 << max(0, (n - 1).bit_length())


@dataclass(frozen=True)
class EngineCapacity:
    """The engine's memory depths, an elaboration parameter: vertices, neighbour entries, triangles;
    ``guard``: whether the build has the step guard's passes and memories (the proposal memory and
    the level scatters), so runs the guarded modes. Both builds fit the ECP5-85F's block RAMs up to
    3072 / 18432 / 6144 (``docs/synthesis.md``). ``lanes``: K datapaths, each on a share of the
    nodes (:data:`LANES`; the images' partition: :func:`entry_lanes`); every depth a multiple of K.
    ``coarse_degree``: the degree of the guarded step's coarse space the build has (its basis and matrix
    memories, :func:`basis_word_layout` and :func:`matrix_word_layout`, and the passes that use them); 0:
    none. A build with one takes the guard and one lane."""

    vertices: int
    entries: int
    triangles: int
    guard: bool = True
    lanes: int = 1
    coarse_degree: int = 0

    def __post_init__(self) -> None:
        for name in ("vertices", "entries", "triangles"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 2:
                raise ValueError(f"EngineCapacity: {name} must be an int >= 2, got {value!r}")
        if not isinstance(self.guard, bool):
            raise ValueError(f"EngineCapacity: guard must be a bool, got {self.guard!r}")
        if not isinstance(self.lanes, int) or isinstance(self.lanes, bool) or self.lanes not in LANES:
            raise ValueError(f"EngineCapacity: lanes must be one of {', '.join(map(str, LANES))}, got {self.lanes!r}")
        degree = self.coarse_degree
        if isinstance(degree, bool) or not isinstance(degree, int) or not 0 <= degree <= COARSE_DEGREE_MAX:
            raise ValueError(f"EngineCapacity: coarse_degree must be an int from 0 (none) to {COARSE_DEGREE_MAX}, "
                             f"got {degree!r}")
        if degree and (not self.guard or self.lanes != 1):
            raise ValueError("EngineCapacity: a coarse space (coarse_degree > 0) is built with the step guard and "
                             "one lane")
        for name in ("vertices", "entries", "triangles"):
            if getattr(self, name) % self.lanes:
                raise ValueError(f"EngineCapacity: {name} = {getattr(self, name)} is not a multiple of lanes = "
                                 f"{self.lanes} (each lane holds an equal share of every memory)")

    @property
    def lane_entries(self) -> int:
        """Neighbour entries one lane's share of the entry memory holds: ``entries / lanes``."""
        return self.entries // self.lanes

    def as_option(self) -> str:
        """``V E T``, as ``--capacity`` takes them."""
        return f"{self.vertices} {self.entries} {self.triangles}"

    @property
    def vertex_index_bits(self) -> int:
        """Bits of a vertex index (``0 .. vertices − 1``)."""
        return (self.vertices - 1).bit_length()

    def count_bits(self, what: str) -> int:
        """Bits of a count ``0 .. capacity`` of ``what`` (``"vertices"``, ``"entries"``, ``"triangles"``)."""
        return getattr(self, what).bit_length()

    @staticmethod
    def least_for(vertices: int) -> tuple[int, int]:
        """``(entries, triangles)`` of the leanest disk mesh of ``vertices`` vertices, a fan: ``V − 2`` triangles
        and ``2V − 3`` edges (``V − E + T = 1``), so ``4V − 6`` neighbour entries."""
        return 4 * vertices - 6, vertices - 2

    @property
    def fillable_vertices(self) -> int:
        """The most vertices a disk mesh within these depths can have (:meth:`least_for` inverted)."""
        return min(self.vertices, (self.entries + 6) // 4, self.triangles + 2)

    def check(self, vertices: int, entries: int, triangles: int) -> None:
        """Refuse counts over capacity: a one-line :class:`FixedPointError` naming the first."""
        for name, count in (("vertices", vertices), ("entries", entries), ("triangles", triangles)):
            if count > getattr(self, name):
                raise FixedPointError(
                    f"the mesh has {count} {'neighbour entries' if name == 'entries' else name}; the engine holds "
                    f"at most {getattr(self, name)} (capacity vertices={self.vertices}, entries={self.entries}, "
                    f"triangles={self.triangles})")

    def check_lanes(self, lane_entries: np.ndarray) -> None:
        """Refuse a lane whose nodes' entries (:func:`entry_lanes`) overflow its share of the entry memory."""
        for k, count in enumerate(lane_entries):
            if count > self.lane_entries:
                raise FixedPointError(
                    f"lane {k} of {self.lanes} (vertices {k}, {k + self.lanes}, {k + 2 * self.lanes}, ...) has {count} "
                    f"neighbour entries; a lane holds at most {self.lane_entries} (capacity entries={self.entries}, "
                    f"lanes={self.lanes})")

    def check_mesh(self, mesh: Mesh) -> None:
        """:meth:`check` of ``mesh``'s own counts (its neighbour entries are its rings': two per edge), which
        no layout changes: callers refuse it before computing one."""
        self.check(mesh.n_vertices, len(mesh.rings.neighbour), mesh.n_faces)
        self.check_lanes(entry_lanes(mesh.rings.indptr, self.lanes)[1])


def entry_lanes(indptr: np.ndarray, lanes: int) -> tuple[np.ndarray, np.ndarray]:
    """How ``lanes`` datapaths share the neighbour entries: lane ``k`` runs the nodes ``k, k + K, k + 2K, …``
    (node ``i`` in lane ``i mod K``, so each node memory is K banks by the index's low bits), each node's
    entries in ring order, from its own share of the entry memory. ``indptr`` (V + 1,) the rings' offsets.

    Returns ``(order, counts)``: ``order[r]`` the node-order entry at lane-major row ``r`` (lane 0's
    entries, then lane 1's, …), ``counts[k]`` lane ``k``'s entries."""
    degrees = np.diff(indptr)
    lane = np.repeat(np.arange(len(degrees)), degrees) % lanes
    return np.argsort(lane, kind="stable"), np.bincount(lane, minlength=lanes)


def lane_rows(counts: np.ndarray, capacity: EngineCapacity) -> np.ndarray:
    """The entry window's index of each lane-major row: lane ``k``'s ``counts[k]`` entries from
    ``k · capacity.lane_entries`` on (consecutive from 0 with one lane)."""
    return np.concatenate([k * capacity.lane_entries + np.arange(n) for k, n in enumerate(counts)]).astype(np.int64)


def node_order_entries(words: np.ndarray, counts: np.ndarray, lanes: int, last: np.ndarray) -> np.ndarray:
    """Lane-major entry rows (:func:`entry_lanes`) back in node order: ``words`` (Σcounts, …) and their
    ``last`` flags; lane ``k``'s ``n``-th node is ``k + n·K``."""
    lane = np.repeat(np.arange(lanes), counts)
    starts = np.repeat(np.concatenate([[0], np.cumsum(counts)[:-1]]), counts)
    ends_before = np.concatenate([[0], np.cumsum(last)[:-1]])  # nodes ended before each row, over all lanes
    local = ends_before - ends_before[starts]  # … and within its lane
    return words[np.argsort(lane + lanes * local, kind="stable")]


#: The engine's capacity unless a flow says otherwise: a 2,000-vertex patch (about 6 entries and 2
#: triangles per vertex) with room to spare, and what the ECP5-85F holds (docs/synthesis.md).
DEFAULT_CAPACITY = EngineCapacity(vertices=2048, entries=12288, triangles=4096)

#: The largest capacity the ECP5-85F's block RAMs hold in the ``default`` formats, with the step guard as
#: without it, at the entries/vertices ≈ 6, triangles/vertices ≈ 2 ratios (counted, docs/synthesis.md).
LARGEST_85F_CAPACITY = EngineCapacity(vertices=3072, entries=18432, triangles=6144)


@dataclass(frozen=True)
class WordField:
    """One field of a memory word or run constant: raw integer of ``width`` bits (``fmt``: its format's name)."""

    name: str
    width: int
    signed: bool = False
    fmt: str | None = None

    @classmethod
    def of(cls, name: str, fs: FormatSet, fmt: str) -> "WordField":
        """A field holding a raw value of ``fs``'s format ``fmt``."""
        f: Format = getattr(fs, fmt)
        return cls(name, f.width, f.signed, fmt)

    @property
    def raw_min(self) -> int:
        return raw_range(self.width, self.signed)[0]

    @property
    def raw_max(self) -> int:
        return raw_range(self.width, self.signed)[1]


@dataclass(frozen=True)
class MemoryLayout:
    """A memory word: fields from bit 0 up, in order; over the bus :attr:`words` words at :attr:`stride`."""

    name: str
    fields: tuple[WordField, ...]
    depth: int

    @property
    def bits(self) -> int:
        return sum(f.width for f in self.fields)

    @property
    def words(self) -> int:
        """Bus words per entry: ``ceil(bits/32)``; word 0 holds bits 31:0."""
        return -(-self.bits // BUS_WORD_BITS)

    @property
    def stride(self) -> int:
        """Bus words between entries: :attr:`words` rounded up to a power of two."""
        return _next_power_of_two(self.words)

    def offsets(self) -> dict[str, int]:
        """``{field: lsb}``."""
        lsb = np.concatenate([[0], np.cumsum([f.width for f in self.fields])[:-1]])
        return {f.name: int(b) for f, b in zip(self.fields, lsb)}

    def pack(self, values: dict[str, np.ndarray]) -> np.ndarray:
        """``(n, words)`` uint32 from one ``(n,)`` array of raw ints per field (range-checked)."""
        n = len(next(iter(values.values())))
        out = np.zeros((n, self.words), dtype=np.uint64)
        for f, lsb in zip(self.fields, self.offsets().values()):
            raw = np.asarray(values[f.name], dtype=np.int64)
            if raw.shape != (n,):
                raise ValueError(f"{self.name}.{f.name}: expected shape ({n},), got {raw.shape}")
            if n and (raw.min() < f.raw_min or raw.max() > f.raw_max):
                raise ValueError(f"{self.name}.{f.name}: raw values [{raw.min()}, {raw.max()}] outside "
                                 f"[{f.raw_min}, {f.raw_max}] ({f.width} bits)")
            bits = raw.astype(np.uint64) & np.uint64((1 << f.width) - 1)  # two's complement in f.width bits
            for word in range(lsb // BUS_WORD_BITS, (lsb + f.width - 1) // BUS_WORD_BITS + 1):
                shift = lsb - word * BUS_WORD_BITS
                part = bits << np.uint64(shift) if shift >= 0 else bits >> np.uint64(-shift)
                out[:, word] |= part & np.uint64(0xFFFF_FFFF)
        return out.astype(np.uint32)

    def unpack(self, words: np.ndarray) -> dict[str, np.ndarray]:
        """Inverse of :meth:`pack`: ``{field: (n,) int64}`` (signed fields sign-extended)."""
        words = np.asarray(words, dtype=np.uint64).reshape(-1, self.words)
        out = {}
        for f, lsb in zip(self.fields, self.offsets().values()):
            bits = np.zeros(len(words), dtype=np.uint64)
            for word in range(lsb // BUS_WORD_BITS, (lsb + f.width - 1) // BUS_WORD_BITS + 1):
                shift = lsb - word * BUS_WORD_BITS
                bits |= words[:, word] >> np.uint64(shift) if shift >= 0 else words[:, word] << np.uint64(-shift)
            raw = (bits & np.uint64((1 << f.width) - 1)).astype(np.int64)
            if f.signed:
                raw = np.where(raw >= 1 << (f.width - 1), raw - (1 << f.width), raw)
            out[f.name] = raw
        return out


def node_word_layout(fs: FormatSet, capacity: EngineCapacity) -> MemoryLayout:
    """Per vertex: position x/y [position], velocity x/y [velocity], inv_mass and inv_mass_barrier [inv_mass]."""
    return MemoryLayout("nodes", (
        WordField.of("position_x", fs, "position"), WordField.of("position_y", fs, "position"),
        WordField.of("velocity_x", fs, "velocity"), WordField.of("velocity_y", fs, "velocity"),
        WordField.of("inv_mass", fs, "inv_mass"), WordField.of("inv_mass_barrier", fs, "inv_mass"),
    ), capacity.vertices)


def entry_word_layout(fs: FormatSet, capacity: EngineCapacity) -> MemoryLayout:
    """Per neighbour entry, nodes in order and each node's entries in ring order (as ``NeighbourStream``):
    neighbour index, ``last`` (the node's last entry), rest [rest_length], the barrier triangle's second
    index, threshold κX* [area] and gain G [barrier_gain] (0: no triangle on this entry)."""
    index = capacity.vertex_index_bits
    return MemoryLayout("entries", (
        WordField("neighbour", index), WordField("last", 1), WordField.of("rest", fs, "rest_length"),
        WordField("second", index), WordField.of("threshold", fs, "area"),
        WordField.of("gain", fs, "barrier_gain"),
    ), capacity.entries)


def triangle_word_layout(fs: FormatSet, capacity: EngineCapacity) -> MemoryLayout:
    """Per triangle: corner indices a, b, c and the host-scaled 3D area [face_area] (``FixedProblem.face_areas``)."""
    index = capacity.vertex_index_bits
    return MemoryLayout("triangles", (
        WordField("a", index), WordField("b", index), WordField("c", index),
        WordField.of("area", fs, "face_area"),
    ), capacity.triangles)


def basis_field_names(degree: int) -> tuple[str, ...]:
    """The basis memory's fields: ``phi_<a><b>`` for the monomial ``u^a·v^b`` of each of
    :func:`~golden_model.coarse.basis_exponents`' but the first (the constant 1, which is not stored)."""
    return tuple(f"phi_{a}{b}" for a, b in basis_exponents(degree)[1:])


def basis_word_layout(capacity: EngineCapacity) -> MemoryLayout:
    """Per vertex, with a coarse space: its basis values ``Φ_i`` but the constant 1, raw s1.16
    (:data:`~golden_model.fixed.coarse.BASIS`, ``CoarseConstants.phi``'s columns 1 on), computed by the host
    from the start layout."""
    return MemoryLayout("basis", tuple(WordField(name, OPERAND_BITS, True) for name in
                                       basis_field_names(capacity.coarse_degree)), capacity.vertices)


def matrix_word_layout(capacity: EngineCapacity) -> MemoryLayout:
    """With a coarse space of ``m`` functions: ``M = (ΦᵀKΦ)⁺`` as ``m²`` signed integers, row-major
    (``CoarseConstants.matrix``, scaled by ``2^matrix_exponent``)."""
    functions = len(basis_exponents(capacity.coarse_degree))
    return MemoryLayout("matrix", (WordField("entry", SUM_BITS, True),), functions * functions)


def memory_layouts(fs: FormatSet, capacity: EngineCapacity) -> dict[str, MemoryLayout]:
    """The memories, by name, in bus-window order: nodes, entries, triangles; with a coarse space the basis and
    the matrix after them."""
    coarse = (basis_word_layout(capacity), matrix_word_layout(capacity)) if capacity.coarse_degree else ()
    return {m.name: m for m in (node_word_layout(fs, capacity), entry_word_layout(fs, capacity),
                                triangle_word_layout(fs, capacity), *coarse)}


def _reciprocal_shift_bits(fs: FormatSet, capacity: EngineCapacity) -> int:
    """Bits of a :class:`Reciprocal` shift (``mantissa_bits + bit_length(total) − 1``) for the largest total
    the capacity allows: Σ of the triangles' [face_area], or Σ of the entries' rest lengths at [error_acc]."""
    area_total = capacity.triangles * fs.face_area.raw_max
    length_total = capacity.entries * fs.rest_length.raw_max << (fs.error_acc.frac_bits - fs.rest_length.frac_bits)
    return (fs.reciprocal.width + max(area_total, length_total).bit_length() - 1).bit_length()


def energy_width(fs: FormatSet, entries: int) -> int:
    """Bits of :func:`~golden_model.fixed.measures.energy_raw` for any layout of a mesh of at most ``entries``
    neighbour entries (an engine's ``capacity.entries``): every entry's ``e = |L − d|`` at most rest_length's and
    ``c·h`` at most barrier_coeff's times area's maximum; the ENERGY registers' width and the energy check's."""
    springs_shift, barrier_shift = energy_shifts(fs)
    springs = 3 * fs.spring.raw_max * entries * fs.rest_length.raw_max ** 2 << springs_shift
    barrier = 2 * entries * fs.barrier_coeff.raw_max * fs.area.raw_max << barrier_shift
    return (springs + barrier).bit_length()


def energy_check_width(fs: FormatSet, square_bits: int, barrier_bits: int) -> int:
    """Bits of :func:`~golden_model.fixed.measures.energy_raw` for any sums the energy check's input registers
    hold (``Σe²`` of ``square_bits``, ``Σc·h`` of ``barrier_bits``, ``½C`` at spring's maximum): its adder's width.
    At least :func:`energy_width` of the capacity those registers are sized for, and a bit more where a
    register's all-ones exceeds what any layout reaches (74 against 73 at ``DEFAULT_CAPACITY``): the ENERGY
    registers take the low :func:`energy_width` bits, which hold every energy a layout has."""
    springs_shift, barrier_shift = energy_shifts(fs)
    half_spring = (1 << (fs.spring.width - 1)) - 1
    return ((3 * half_spring * ((1 << square_bits) - 1) << springs_shift)
            + (2 * ((1 << barrier_bits) - 1) << barrier_shift)).bit_length()


#: The MAX_ITER register's field: what any run through the engine can ask for (:func:`check_run_limits`).
MAX_ITER_FIELD = WordField("max_iter", ITERATION_BITS)


def lane_count_fields(capacity: EngineCapacity) -> tuple[WordField, ...]:
    """With more than one lane, each lane's neighbour entries (``lane0_entries``, …; :func:`entry_lanes`),
    which the run constants carry after ``entries`` (their total); none with one lane."""
    if capacity.lanes == 1:
        return ()
    return tuple(WordField(f"lane{k}_entries", capacity.lane_entries.bit_length()) for k in range(capacity.lanes))


def lane_entry_counts(constants: dict[str, int], capacity: EngineCapacity) -> np.ndarray:
    """Each lane's neighbour entries as the run constants give them (one lane: ``entries``)."""
    if capacity.lanes == 1:
        return np.array([constants["entries"]])
    return np.array([constants[f.name] for f in lane_count_fields(capacity)])


def coarse_constant_fields(capacity: EngineCapacity) -> tuple[WordField, ...]:
    """With a coarse space, the run constants that follow the others: ``coarse`` (1: the guarded step takes the
    coarse move) and ``matrix_exponent``, the matrix memory's scale; none without one."""
    if not capacity.coarse_degree:
        return ()
    return WordField("coarse", 1), WordField("matrix_exponent", MATRIX_EXPONENT_BITS, True)


def run_constant_fields(fs: FormatSet, capacity: EngineCapacity) -> tuple[WordField, ...]:
    """The run constants (raw ints), in register order; those of :data:`MODE_FIELDS` share the ``MODE``
    register: ``mode``, the run mode's code (:data:`~golden_model.modes.RUN_MODES`), and ``barrier``.

    ``saturation_limit`` (0: never) stops a run as ``diverged`` once that many saturation
    events were counted; the golden model's own loop never stops on saturation (limit 0).
    """
    shift = _reciprocal_shift_bits(fs, capacity)
    return (
        WordField("vertices", capacity.count_bits("vertices")),
        WordField("entries", capacity.count_bits("entries")),
        *lane_count_fields(capacity),
        WordField("triangles", capacity.count_bits("triangles")),
        WordField("mode", MODE_CODE_BITS),
        WordField("barrier", 1),
        WordField.of("half_spring", fs, "spring"),
        WordField.of("damping", fs, "damping"),
        WordField.of("dt", fs, "dt"),
        WordField.of("area_reciprocal", fs, "reciprocal"),
        WordField("area_shift", shift),
        WordField.of("length_reciprocal", fs, "reciprocal"),
        WordField("length_shift", shift),
        WordField.of("tol_area", fs, "error"),
        WordField.of("tol_shape", fs, "error"),
        WordField("tol_energy", ENERGY_TOL_INT_BITS + ENERGY_TOL_FRAC_BITS),
        MAX_ITER_FIELD,
        WordField("saturation_limit", SATURATION_BITS),
        WordField("energy_floor", energy_width(fs, capacity.entries)),
        *coarse_constant_fields(capacity),
    )


@dataclass(frozen=True, eq=False)
class EngineImage:
    """What the host loads: three memories as ``(n, words)`` uint32 (``n`` the mesh's counts), and the
    run constants as raw ints (keys: :func:`run_constant_fields`); with a coarse space
    (``capacity.coarse_degree``) the basis (a row per vertex) and the matrix memories too."""

    capacity: EngineCapacity
    nodes: np.ndarray
    entries: np.ndarray
    triangles: np.ndarray
    constants: dict[str, int] = field(default_factory=dict)
    basis: np.ndarray | None = None
    matrix: np.ndarray | None = None

    def memories(self) -> dict[str, np.ndarray]:
        coarse = {"basis": self.basis, "matrix": self.matrix} if self.capacity.coarse_degree else {}
        return {"nodes": self.nodes, "entries": self.entries, "triangles": self.triangles, **coarse}

    def rows(self, name: str) -> np.ndarray:
        """The index in its memory window of each row of memory ``name``: from 0 up, except the entries of
        more than one lane (:func:`lane_rows`)."""
        n = len(self.memories()[name])
        if name != "entries" or self.capacity.lanes == 1:
            return np.arange(n)
        return lane_rows(lane_entry_counts(self.constants, self.capacity), self.capacity)


def _run_constants(problem: FixedProblem, capacity: EngineCapacity, lane_counts: np.ndarray) -> dict[str, int]:
    fs, params, stream = problem.fs, problem.params, problem.stream
    mode = params.mode
    fixed_step = mode.step is Step.FIXED
    rule = StopRule.of(params, fs, energy_floor_raw(problem))
    constants = {
        "vertices": len(stream.indptr) - 1, "entries": len(stream.neighbour), "triangles": len(problem.face_areas),
        **{f.name: int(n) for f, n in zip(lane_count_fields(capacity), lane_counts)},
        "mode": mode.code, "barrier": int(stream.barrier is not None),
        "half_spring": problem.half_spring, "damping": problem.damping,
        "dt": int(quantize(params.dt, fs.dt, HOST_ROUNDING, SAT)) if fixed_step else 0,
        "area_reciprocal": problem.area_reciprocal.mantissa, "area_shift": problem.area_reciprocal.shift,
        "length_reciprocal": problem.length_reciprocal.mantissa, "length_shift": problem.length_reciprocal.shift,
        "tol_area": rule.area, "tol_shape": rule.shape,  # (StopRule clamps them to error's maximum)
        "tol_energy": rule.energy, "max_iter": params.max_iter, "saturation_limit": 0,
        "energy_floor": rule.floor,
    }
    if capacity.coarse_degree:
        constants |= {"coarse": int(problem.coarse is not None),
                      "matrix_exponent": 0 if problem.coarse is None else problem.coarse.matrix_exponent}
    check_run_limits(params)
    for f in run_constant_fields(fs, capacity):
        _check_fits(f, constants[f.name])
    return constants


def _check_fits(f: WordField, value: int) -> None:
    if not f.raw_min <= value <= f.raw_max:
        raise FixedPointError(f"run constant {f.name} = {value} does not fit the engine's {f.width}-bit register "
                              f"(max {f.raw_max})")


#: The momentum dynamics as the engine runs it: without the step guard, stopped by Algorithm 1's
#: one-iteration energy rule (``FlattenParams(dynamics="momentum", **UNGUARDED)``).
UNGUARDED = {"guard": False, "energy_window": 1}


def check_engine_params(params, capacity: EngineCapacity | None = None) -> None:
    """Refuse, in one line, a stop rule's window the engine does not have (the guard's
    :data:`~golden_model.guard.ENERGY_WINDOW`, one iteration without it), and the guarded step on a
    ``capacity`` built without the guard, and a coarse space the ``capacity`` does not have (of another degree;
    ``None``: the engine's capacity is not known yet, and :func:`build_image` checks it)."""
    if capacity is not None and params.coarse_degree and params.coarse_degree != capacity.coarse_degree:
        built = capacity.coarse_degree
        raise FixedPointError(f"this engine's coarse space is of degree {built}, not {params.coarse_degree}: use "
                              f"--coarse-degree {built} or 0" if built else
                              "this engine was built without a coarse space: use --coarse-degree 0, or build the "
                              f"engine with one (springflat verilog --coarse-degree {params.coarse_degree} --out DIR)")
    if capacity is not None and params.guard and not capacity.guard:
        raise FixedPointError(f"this engine was built without the step guard, so it does not run "
                              f"'{params.mode.name}': use --no-guard, or an engine built with the guard")
    window = image_energy_window(params.mode)
    if params.energy_window != window:
        hint = (f"--energy-window {window}" if params.guard else
                "--energy-window 1 (or the guard, with its window)" if params.mode.step is Step.MOMENTUM else
                "--energy-window 1")  # (the paper dynamics has no guard)
        raise FixedPointError(f"SpringflatEngine's stop rule measures the energy change over {window} "
                              f"{'accepted iterations' if params.guard else 'iteration'} in this mode, not "
                              f"{params.energy_window}: use {hint}")


def check_run_limits(params) -> None:
    """Refuse, in one line, an ``N_max`` beyond the engine's MAX_ITER register (:data:`ITERATION_BITS`) or an ``ε``
    beyond its TOL_ENERGY register: the run constants no layout changes, which :func:`build_image` checks with
    the rest, and a whole run through the engine (``flatten --engine rtl|board``) before its start is computed."""
    _check_fits(MAX_ITER_FIELD, params.max_iter)
    if tol_energy_raw(params.tol_energy) >> (ENERGY_TOL_INT_BITS + ENERGY_TOL_FRAC_BITS):  # (said as given)
        raise FixedPointError(f"--tol-energy {params.tol_energy:g} does not fit the engine's TOL_ENERGY register "
                              f"(u{ENERGY_TOL_INT_BITS}.{ENERGY_TOL_FRAC_BITS}: below {2**ENERGY_TOL_INT_BITS}); use a "
                              "smaller value")


def build_image(problem: FixedProblem, capacity: EngineCapacity) -> EngineImage:
    """The memory images and run constants of ``problem`` for an engine of ``capacity``: the entries
    lane-major (:func:`entry_lanes`; node order with one lane), written at :meth:`EngineImage.rows`.

    Raises :class:`FixedPointError` (one line) for a mesh over capacity (a lane's share of the
    entries included), or a parameter the engine's registers cannot hold.
    """
    fs, stream = problem.fs, problem.stream
    n_vertices, n_entries = len(stream.indptr) - 1, len(stream.neighbour)
    capacity.check(n_vertices, n_entries, len(problem.face_areas))
    lane_order, lane_counts = entry_lanes(stream.indptr, capacity.lanes)
    capacity.check_lanes(lane_counts)
    check_fixed_params(problem.params, fs)
    check_engine_params(problem.params, capacity)
    constants = _run_constants(problem, capacity, lane_counts)
    layouts = memory_layouts(fs, capacity)
    positions = problem.initial_positions
    nodes = layouts["nodes"].pack({
        "position_x": positions[:, 0], "position_y": positions[:, 1],
        "velocity_x": np.zeros(n_vertices, np.int64), "velocity_y": np.zeros(n_vertices, np.int64),
        "inv_mass": stream.inv_mass, "inv_mass_barrier": stream.header_inv_mass_barrier})
    last = np.zeros(n_entries, np.int64)
    last[stream.indptr[1:] - 1] = 1
    barrier = stream.barrier
    zeros = np.zeros(n_entries, np.int64)
    entries = layouts["entries"].pack({
        "neighbour": stream.neighbour, "last": last, "rest": stream.rest,
        "second": stream.neighbour if barrier is None else barrier.second,
        "threshold": zeros if barrier is None else barrier.threshold,
        "gain": zeros if barrier is None else barrier.gain})[lane_order]
    faces = problem.mesh.faces
    triangles = layouts["triangles"].pack({"a": faces[:, 0], "b": faces[:, 1], "c": faces[:, 2],
                                           "area": problem.face_areas})
    if not capacity.coarse_degree:
        return EngineImage(capacity, nodes, entries, triangles, constants)
    coarse = problem.coarse
    functions = len(basis_exponents(capacity.coarse_degree))
    phi = np.zeros((n_vertices, functions), np.int64) if coarse is None else coarse.phi
    matrix = np.zeros((functions, functions), np.int64) if coarse is None else coarse.matrix
    basis = basis_word_layout(capacity).pack(dict(zip(basis_field_names(capacity.coarse_degree), phi[:, 1:].T)))
    return EngineImage(capacity, nodes, entries, triangles, constants, basis,
                       matrix_word_layout(capacity).pack({"entry": matrix.reshape(-1)}))


def decode_coarse(image: "EngineImage") -> CoarseConstants | None:
    """The coarse space's constants the basis and matrix memories and the run constants hold (the constant
    basis function prepended), or ``None`` where the run takes none (no coarse space built, or ``coarse`` 0)."""
    capacity, c = image.capacity, image.constants
    if not capacity.coarse_degree or not c["coarse"]:
        return None
    columns = basis_word_layout(capacity).unpack(image.basis[:c["vertices"]])
    phi = np.column_stack([np.full(c["vertices"], 1 << BASIS_FRAC_BITS, np.int64),
                           *(columns[name] for name in basis_field_names(capacity.coarse_degree))])
    functions = phi.shape[1]
    matrix = matrix_word_layout(capacity).unpack(image.matrix)["entry"][:functions * functions]
    return CoarseConstants(phi, matrix.reshape(functions, functions), c["matrix_exponent"])


def decode_nodes(words: np.ndarray, fs: FormatSet, capacity: EngineCapacity) -> tuple[np.ndarray, np.ndarray,
                                                                                       np.ndarray, np.ndarray]:
    """Node memory words → ``(positions (V, 2) [position], velocities (V, 2) [velocity], inv_mass (V,),
    inv_mass_barrier (V,) [inv_mass])``."""
    f = node_word_layout(fs, capacity).unpack(words)
    return (np.column_stack([f["position_x"], f["position_y"]]), np.column_stack([f["velocity_x"], f["velocity_y"]]),
            f["inv_mass"], f["inv_mass_barrier"])


def decode_entries(words: np.ndarray, fs: FormatSet, capacity: EngineCapacity, barrier: bool,
                   lane_counts: np.ndarray | None = None, vertices: int | None = None) -> tuple[
                       np.ndarray, np.ndarray, np.ndarray, BarrierEntries | None]:
    """Entry memory words → ``(indptr (V+1,) from the last flags, neighbour, rest, barrier entries or None)``,
    in node order: ``words`` in node order, or lane-major with each lane's ``lane_counts`` (:func:`entry_lanes`).
    With ``vertices``, entries whose ``last`` flags do not end exactly each lane's nodes (:func:`unended_nodes`)
    are a one-line :class:`EntryCountError`: counts that do not match the entries."""
    layout = entry_word_layout(fs, capacity)
    f = layout.unpack(words)
    counts = np.array([len(words)]) if lane_counts is None else lane_counts
    if vertices is not None and (unended := unended_nodes(f["last"], counts, vertices)) is not None:
        raise EntryCountError(f"{unended}: the entry counts do not match the entries")
    if len(counts) > 1:
        f = layout.unpack(node_order_entries(words, counts, len(counts), f["last"]))
    indptr = np.concatenate([[0], np.flatnonzero(f["last"]) + 1])
    entries = BarrierEntries(f["second"], f["threshold"], f["gain"]) if barrier else None
    return indptr, f["neighbour"], f["rest"], entries


class EntryCountError(ValueError):
    """Entry counts that do not end the entries' nodes (:func:`unended_nodes`), in one line."""


def unended_nodes(last: np.ndarray, counts: np.ndarray, vertices: int) -> str | None:
    """Where the entries' ``last`` flags (lane-major: lane ``k``'s ``counts[k]`` rows, :func:`entry_lanes`) do not
    end exactly each lane's nodes (lane ``k`` runs nodes ``k, k + K, …`` of ``vertices``), what is wrong, in a
    few words; ``None`` where they do (every image :func:`build_image` makes)."""
    lanes, first = len(counts), 0
    for k, n in enumerate(counts):
        rows, first = last[first:first + n].astype(bool), first + n
        nodes, ends = len(range(k, vertices, lanes)), int(np.count_nonzero(rows))
        whose = (f"lane {k}'s" if lanes > 1 else "the") + f" {n} {'entry' if n == 1 else 'entries'}"
        if n > 0 and not rows[-1]:
            return f"{whose} stop inside a node, after {ends} of {'its' if lanes > 1 else 'the'} {nodes} nodes' ends"
        if ends != nodes:
            return f"{whose} end {ends} nodes, not {'its' if lanes > 1 else 'the'} {nodes}"
    return None


def decode_triangles(words: np.ndarray, fs: FormatSet, capacity: EngineCapacity) -> tuple[np.ndarray, np.ndarray]:
    """Triangle memory words → ``(faces (F, 3), areas (F,) [face_area])``."""
    f = triangle_word_layout(fs, capacity).unpack(words)
    return np.column_stack([f["a"], f["b"], f["c"]]), f["area"]


def constant_fault(constants: dict[str, int], fs: FormatSet, capacity: EngineCapacity) -> str | None:
    """What the engine answers to START with these run constants: ``"no-mesh"`` (no vertices: nothing
    loaded since reset), ``"bad-constants"`` (a count over capacity or zero, with K > 1 lanes ``lane{k}_entries``
    that do not add up to ``entries`` or one over its share, a reciprocal that is not a
    u1.F mantissa or whose shift is too small for :meth:`Reciprocal.normalise`, a mode code the engine
    does not run, a guarded mode on a build without the guard, the coarse move asked of an unguarded mode, a zero
    fixed step, no iterations), or
    ``None`` (the run starts)."""
    if constants["vertices"] == 0:
        return "no-mesh"
    lane_counts = lane_entry_counts(constants, capacity)
    counts_ok = all(0 < constants[n] <= getattr(capacity, n) for n in ("vertices", "entries", "triangles")) \
        and lane_counts.sum() == constants["entries"] and lane_counts.max() <= capacity.lane_entries
    top = 1 << (fs.reciprocal.width - 1)
    reciprocals_ok = all(top <= constants[f"{k}_reciprocal"] < 2 * top
                         and constants[f"{k}_shift"] >= fs.error.frac_bits + 2 for k in ("area", "length"))
    mode = image_mode(constants)
    step_ok = mode is not None and (mode.step is not Step.FIXED or constants["dt"] > 0) \
        and (capacity.guard or not mode.guarded) and (mode.guarded or not constants.get("coarse", 0))
    if not (counts_ok and reciprocals_ok and step_ok and constants["max_iter"] > 0):
        return "bad-constants"
    return None


@dataclass(frozen=True, eq=False)
class ImageRunResult:
    """What the engine holds after a run: the node memory, STATUS.result, and the result registers."""

    nodes: np.ndarray  # (V, words) uint32: the node memory written back in place
    status: str  # one of RESULTS
    iterations: int
    area_error: int  # E_S raw [error] of the final layout
    shape_error: int  # E_C raw [error]
    energy: int  # energy_raw of the final layout
    saturations: int  # saturation events, stopped at 2**SATURATION_BITS - 1
    positions: np.ndarray  # (V, 2) raw [position]
    velocities: np.ndarray  # (V, 2) raw [velocity]
    guard: object = None  # the guarded mode's GuardRecord (rejected steps, clipped and frozen node steps)


def image_mode(constants: dict[str, int]) -> RunMode | None:
    """The run mode ``MODE.mode`` selects, or ``None`` for a code of no mode the engine runs (START answers
    ``bad-constants``)."""
    return next((m for m in ENGINE_RUN_MODES if m.code == constants["mode"]), None)


def image_energy_window(mode: RunMode) -> int:
    """The stop rule's window ``W`` the engine runs ``mode`` with: the guard's :data:`ENERGY_WINDOW`
    (accepted iterations), else Algorithm 1's one iteration."""
    return ENERGY_WINDOW if mode.guarded else 1


def run_image(image: EngineImage, fs: FormatSet) -> ImageRunResult:
    """Algorithm 1 from START to done on the decoded images, as the engine runs it: the one controller
    model (:class:`~golden_model.fixed.controller.Controller`) on what the memories and run constants
    hold, ``diverged`` when ``saturation_limit`` events were counted. Entry counts that START accepts but
    that do not end the entries' nodes (a host's own image, not :func:`build_image`'s) are a one-line
    :class:`EntryCountError`: the engine's run of them is undefined."""
    c, capacity = image.constants, image.capacity
    positions, velocities, inv_mass, inv_mass_barrier = decode_nodes(image.nodes, fs, capacity)
    fault = constant_fault(c, fs, capacity)
    if fault is not None:
        return ImageRunResult(image.nodes.copy(), fault, 0, 0, 0, 0, 0, positions, velocities)
    n = c["vertices"]
    try:
        indptr, neighbour, rest, barrier = decode_entries(image.entries[:c["entries"]], fs, capacity,
                                                          bool(c["barrier"]), lane_entry_counts(c, capacity), n)
    except EntryCountError as exc:
        raise EntryCountError(f"run_image: {exc}, and the engine's run is undefined (on the RTL such a run never ends, "
                         "nor does ABORT's drain: only a reset recovers)") from None
    stream = NeighbourStream(indptr, neighbour, rest, inv_mass[:n], barrier, inv_mass_barrier[:n])
    faces, areas = decode_triangles(image.triangles[:c["triangles"]], fs, capacity)
    setup = Setup(fs, image_mode(c), stream, faces, areas, c["half_spring"], c["damping"], c["dt"],
                  Reciprocal(c["area_reciprocal"], c["area_shift"]), Reciprocal(c["length_reciprocal"], c["length_shift"]),
                  StopRule(c["tol_area"], c["tol_shape"], c["tol_energy"], c["energy_floor"]), c["max_iter"],
                  image_energy_window(image_mode(c)), c["saturation_limit"], coarse=decode_coarse(image))
    counter = SaturationCounter()
    controller = Controller(setup, positions[:n], velocities[:n], counter)
    status, k = controller.run()
    positions, velocities = controller.raw_positions, controller.raw_velocities
    layout = node_word_layout(fs, capacity)
    nodes = image.nodes.copy()
    nodes[:n] = layout.pack({"position_x": positions[:, 0], "position_y": positions[:, 1],
                             "velocity_x": velocities[:, 0], "velocity_y": velocities[:, 1],
                             "inv_mass": inv_mass[:n], "inv_mass_barrier": inv_mass_barrier[:n]})
    saturations = min(counter.total, (1 << SATURATION_BITS) - 1)
    return ImageRunResult(nodes, status, k, controller.errors[0], controller.errors[1], controller.energy_raw,
                          saturations, positions, velocities, controller.guard)
