"""The stream payload layouts of the datapath, in one place (``lib.data`` layouts built from a format set).

Every field's width comes from :class:`~golden_model.fixed.FormatSet`; the cocotb benches pack
and unpack with the same layouts (:mod:`sim.payloads`), and the Verilog export describes them in
``interface.json``.
"""

from __future__ import annotations

from amaranth.hdl import ShapeCastable, signed, unsigned
from amaranth.lib import data

from golden_model.fixed import MAX_PRODUCT_WIDTH, Format, FormatSet
from golden_model.guard import GUARD_LEVELS, SCALE_MAX_SHIFT
from golden_model.engine_spec.image import MemoryLayout

from .fixedpoint import shape_of

__all__ = ["vector_layout", "node_layout", "barrier_layout", "neighbour_layout", "entry_layout", "result_layout",
           "force_entry_layout", "node_force_layout", "integrator_input_layout", "integrator_output_layout",
           "step_layout", "errors_layout", "FORCE_ENTRY_EVENTS", "FORCE_NODE_EVENTS", "INTEGRATOR_EVENTS",
           "STEP_EVENTS", "COARSE_INTEGRATOR_EVENTS", "force_saturations_max", "saturations_shape"]

#: Saturation events one neighbour entry of the force pass can raise, by the golden model's
#: ``SaturationCounter`` name (``node_terms``: ``neighbour_terms`` and ``barrier_terms``): elements
#: per entry. ``delta`` is the spring's Δ (x, y) and the barrier's Δb (x, y); the barrier's events
#: (its Δb, ``area`` … ``barrier_force``) count only while the barrier is on.
FORCE_ENTRY_EVENTS = {"delta": 4, "length_sq": 1, "rsqrt": 1, "one_minus_dr": 1, "length": 1, "spring": 1,
                      "force": 2, "area": 1, "area_short": 1, "barrier_coeff": 1, "barrier_edge": 2,
                      "barrier_force": 2}
#: … and one node of the force pass, once its sums leave the accumulators.
FORCE_NODE_EVENTS = {"force_acc": 2, "error_acc": 1}
#: Saturation events of one node in the integrate stage (``integrate`` or ``integrate_momentum``,
#: and, in the momentum dynamics, ``node_power``); the paper's step raises all but ``power``, the
#: momentum step only ``accel``, ``velocity``, ``position`` and ``power``.
INTEGRATOR_EVENTS = {"accel": 2, "position_step": 2, "position": 2, "velocity_step": 2, "velocity": 2,
                     "damping": 2, "power": 1}
#: … and, in an integrator built with the coarse move's input, the sum ``a + coarse`` saturated to [accel]
#: (:func:`golden_model.fixed.guard.proposal`).
COARSE_INTEGRATOR_EVENTS = {"accel": 2}
#: Saturation events of one step (``step_size``): ``lut_input`` per lane (a u1.F error above 1),
#: ``dt`` twice (the requantised sum, then with the constant added), ``half_dt_sq``.
STEP_EVENTS = {"lut_input": 2, "dt": 2, "half_dt_sq": 1}


def force_saturations_max(fs: FormatSet) -> int:
    """The most saturation events one node of the force pass can raise: ``max_degree`` entries
    of :data:`FORCE_ENTRY_EVENTS` and the node's own :data:`FORCE_NODE_EVENTS`."""
    return fs.max_degree * sum(FORCE_ENTRY_EVENTS.values()) + sum(FORCE_NODE_EVENTS.values())


def saturations_shape(most: int):
    """The ``saturations`` field of a beat that can carry up to ``most`` events."""
    return unsigned(most.bit_length())


def vector_layout(fmt: Format) -> data.StructLayout:
    """A 2D vector of raw ``fmt`` values: fields ``x``, ``y``."""
    return data.StructLayout({"x": shape_of(fmt), "y": shape_of(fmt)})


def node_layout(fs: FormatSet) -> data.StructLayout:
    """A node's state: ``position`` [position], ``velocity`` [velocity], ``inv_mass`` [inv_mass]
    and ``inv_mass_barrier`` [inv_mass], the weight used instead while one of the node's
    triangles is inside the fold barrier (equal to ``inv_mass`` where that does not apply)."""
    return data.StructLayout({
        "position": vector_layout(fs.position),
        "velocity": vector_layout(fs.velocity),
        "inv_mass": shape_of(fs.inv_mass),
        "inv_mass_barrier": shape_of(fs.inv_mass),
    })


def barrier_layout(fs: FormatSet) -> data.StructLayout:
    """An entry's fold-barrier triangle: the third corner's ``position``, ``threshold`` κX* [area], ``gain`` G [barrier_gain]."""
    return data.StructLayout({
        "second": vector_layout(fs.position),
        "threshold": shape_of(fs.area),
        "gain": shape_of(fs.barrier_gain),
    })


def neighbour_layout(fs: FormatSet) -> data.StructLayout:
    """A neighbour entry's ``position`` [position] and the edge's ``rest`` length [rest_length]."""
    return data.StructLayout({"position": vector_layout(fs.position), "rest": shape_of(fs.rest_length)})


def entry_layout(fs: FormatSet) -> data.StructLayout:
    """One input beat: a neighbour entry, with its node's header on the node's first entry.

    ``first``/``last`` mark a node's first and last neighbour entries; ``node``
    is read only when ``first`` is set; ``neighbour`` holds the neighbour's
    ``position`` and the edge's ``rest`` length [rest_length]; ``barrier`` the
    entry's fold-barrier triangle (``gain`` 0: none).
    """
    return data.StructLayout({
        "first": unsigned(1),
        "last": unsigned(1),
        "node": node_layout(fs),
        "neighbour": neighbour_layout(fs),
        "barrier": barrier_layout(fs),
    })


def result_layout(fs: FormatSet) -> data.StructLayout:
    """One output beat: the node's new ``position``, ``velocity``, ``error_sum`` Σ|L − d| [error_acc]
    and ``power`` F·V [power] (force and velocity of the *input* state)."""
    return data.StructLayout({
        "position": vector_layout(fs.position),
        "velocity": vector_layout(fs.velocity),
        "error_sum": shape_of(fs.error_acc),
        "power": shape_of(fs.power),
    })


def force_entry_layout(fs: FormatSet) -> data.StructLayout:
    """One beat of the force pass (:class:`~hdl.force_pass.ForcePass`): a neighbour entry of a node.

    ``first``/``last`` mark the node's first and last entries; ``position`` is the node's own
    ``P_i`` [position], read only on ``first``; ``neighbour`` and ``barrier`` as in
    :func:`entry_layout`. No velocity or weight: the force pass does not need them.
    """
    return data.StructLayout({
        "first": unsigned(1),
        "last": unsigned(1),
        "position": vector_layout(fs.position),
        "neighbour": neighbour_layout(fs),
        "barrier": barrier_layout(fs),
    })


def node_force_layout(fs: FormatSet, energy: bool = False, saturations: bool = False) -> data.StructLayout:
    """One node's result of the force pass.

    ``force`` ΣF [force_acc] and ``error_sum`` Σ|L − d| [error_acc], both saturated; ``inside``:
    one of the node's triangles is inside the fold barrier (``h > 0``). With ``energy``, the
    node's exact energy partials too: ``error_squares`` Σe² (``e = |L − d|`` raw [rest_length],
    squared: raw at twice its fraction bits) and ``barrier_energy`` Σc·h (raw [barrier_coeff]·[area],
    ``h ≥ 0``), each wide enough for ``max_degree`` terms
    (:attr:`golden_model.fixed.pipeline.NodeTerms.error_squares` / ``barrier_energies``).
    With ``saturations``, ``saturations``: the node's saturation events (its entries' and its
    sums'), up to :func:`force_saturations_max`.
    """
    fields = {"force": vector_layout(fs.force_acc), "error_sum": shape_of(fs.error_acc), "inside": unsigned(1)}
    if energy:
        acc = fs.accumulators()  # c ≥ 0 and h < 2**(area.width − 1): both unsigned
        fields["error_squares"] = unsigned(acc["error_squares"][1])
        fields["barrier_energy"] = unsigned(acc["barrier_energy"][1])
    if saturations:
        fields["saturations"] = saturations_shape(force_saturations_max(fs))
    return data.StructLayout(fields)


def integrator_input_layout(fs: FormatSet, side: ShapeCastable | None = None,
                            coarse: bool = False) -> data.StructLayout:
    """One node into the integrate stage (:class:`~hdl.integrator.Integrator`): its state ``node``
    (:func:`node_layout`), ``force`` ΣF [force_acc] and ``inside`` (the barrier's weight applies);
    with ``side``, an opaque field of that shape carried to the output unchanged; with ``coarse``, the
    node's coarse move ``coarse`` [accel] (:class:`~hdl.coarse_node.CoarseNode`'s)."""
    fields = {"node": node_layout(fs), "force": vector_layout(fs.force_acc), "inside": unsigned(1)}
    if side is not None:
        fields["side"] = side
    if coarse:
        fields["coarse"] = vector_layout(fs.accel)
    return data.StructLayout(fields)


def integrator_output_layout(fs: FormatSet, side: ShapeCastable | None = None,
                             saturations: bool = False, coarse: bool = False) -> data.StructLayout:
    """One node out of the integrate stage: new ``position`` [position], new ``velocity``
    [velocity] (damped), ``power`` F·V [power] of the input state; with ``side``, the input's
    ``side`` field; with ``saturations``, ``saturations``: the node's saturation events (up to
    :data:`INTEGRATOR_EVENTS`, and :data:`COARSE_INTEGRATOR_EVENTS` with ``coarse``)."""
    fields = {"position": vector_layout(fs.position), "velocity": vector_layout(fs.velocity),
              "power": shape_of(fs.power)}
    if side is not None:
        fields["side"] = side
    if saturations:
        fields["saturations"] = saturations_shape(sum(INTEGRATOR_EVENTS.values())
                                                  + (sum(COARSE_INTEGRATOR_EVENTS.values()) if coarse else 0))
    return data.StructLayout(fields)


def step_layout(fs: FormatSet) -> data.StructLayout:
    """``dt`` [dt] and ``half_dt_sq`` [half_dt_sq]."""
    return data.StructLayout({"dt": shape_of(fs.dt), "half_dt_sq": shape_of(fs.half_dt_sq)})


def errors_layout(fs: FormatSet) -> data.StructLayout:
    """``area_error`` (E_S) and ``shape_error`` (E_C), both [error]."""
    return data.StructLayout({"area_error": shape_of(fs.error), "shape_error": shape_of(fs.error)})


# ---------------------------------------------------------------- the controller's units
# (hdl/area_error.py, hdl/controller_units.py)

__all__ += ["triangle_layout", "certificate_layout", "certificate_level_shape", "certificate_result_layout",
            "commit_input_layout", "commit_output_layout",
            "decision_input_layout", "decision_output_layout", "area_saturations_layout",
            "normalise_layout", "energy_sums_layout", "PASS_SUMS", "pass_sum_shapes", "energy_result_layout",
            "word_layout", "weight_word_layout", "force_word_layout"]


def triangle_layout(fs: FormatSet) -> data.StructLayout:
    """One triangle of the area pass: its corners ``a``, ``b``, ``c`` [position] in the layout
    and the host's area ``area`` A [face_area] (the same triangle in the mesh)."""
    return data.StructLayout({
        "a": vector_layout(fs.position),
        "b": vector_layout(fs.position),
        "c": vector_layout(fs.position),
        "area": shape_of(fs.face_area),
    })


def certificate_layout(fs: FormatSet) -> data.StructLayout:
    """One triangle of the guard's certificate: its corners ``a``, ``b``, ``c`` [position], their
    proposed moves ``move_a``, ``move_b``, ``move_c`` [velocity] and the host's area ``area`` [face_area]."""
    return data.StructLayout({
        "a": vector_layout(fs.position), "b": vector_layout(fs.position), "c": vector_layout(fs.position),
        "move_a": vector_layout(fs.velocity), "move_b": vector_layout(fs.velocity),
        "move_c": vector_layout(fs.velocity),
        "area": shape_of(fs.face_area),
    })


def certificate_level_shape():
    """A triangle's guard level: 0 … GUARD_LEVELS (its corners move by 2^-level of their proposals), or
    GUARD_LEVELS + 1 (they do not move)."""
    return unsigned((GUARD_LEVELS + 1).bit_length())


def certificate_result_layout() -> data.StructLayout:
    """A triangle's certificate: its ``level`` (:func:`certificate_level_shape`) and ``stuck``, bit ``k``
    set when corner ``k``'s own move alone fails the triangle's certificate at ``2^-GUARD_LEVELS`` (the
    triangle's part of ``stuck_nodes_raw``)."""
    return data.StructLayout({"level": certificate_level_shape(), "stuck": 3})


def commit_input_layout(fs: FormatSet) -> data.StructLayout:
    """One node of the guarded commit (:class:`~hdl.guard_commit.GuardCommit`): its ``position`` P
    [position]; ``velocity`` [velocity], the proposal V' (0 for a stuck node) to commit, or the
    committed move V to roll back; its three slot ``levels`` (each :func:`certificate_level_shape`,
    the node's level their largest); ``stuck`` (held still) and ``rollback``."""
    return data.StructLayout({
        "position": vector_layout(fs.position), "velocity": vector_layout(fs.velocity),
        "levels": data.ArrayLayout(certificate_level_shape(), 3), "stuck": 1, "rollback": 1,
    })


def commit_output_layout(fs: FormatSet) -> data.StructLayout:
    """The node committed or rolled back: its new ``position`` [position] and ``velocity`` [velocity]
    (the move taken; 0 after a rollback) and its final ``level`` (:func:`certificate_level_shape`)."""
    return data.StructLayout({"position": vector_layout(fs.position), "velocity": vector_layout(fs.velocity),
                              "level": certificate_level_shape()})


def decision_input_layout(energy_bits: int, coarse: bool = False) -> data.StructLayout:
    """One measurement: its exact ``energy`` (``energy_raw``), ``first`` (the run's start layout: no step
    to judge) and ``with_momentum`` (the step carried momentum, β > 0: a rejection restarts it rather
    than halving the scale); with ``coarse``, ``clipped`` too (the guard shortened a node's move in the step to
    ``2^-CLIP_HANDOVER_LEVEL`` or less: :func:`golden_model.coarse.clipped_deep`)."""
    return data.StructLayout({"energy": unsigned(energy_bits), "first": 1, "with_momentum": 1,
                              **({"clipped": 1} if coarse else {})})


def decision_output_layout(energy_bits: int) -> data.StructLayout:
    """The decision: ``accepted`` (the energy did not rise), ``energy`` (the kept layout's), ``settled``
    (the window is ready and its energy test passes), ``stalled`` (the scale passed its last halving)
    and the step scale's ``shift`` for the next proposal (``s = 2^-shift``)."""
    return data.StructLayout({"accepted": 1, "energy": unsigned(energy_bits), "settled": 1, "stalled": 1,
                              "shift": range(SCALE_MAX_SHIFT + 2)})


def area_saturations_layout(fs: FormatSet) -> data.StructLayout:
    """Saturation events of one area pass, named as the golden model's ``SaturationCounter``
    counts them: ``face_edge`` (edge components, up to 4 per triangle), ``face_area`` (triangles)
    and ``area_sum`` (1 if the pass's sum saturated).

    Wide enough for every pass the host accepts: fewer than ``2**(63 − face_area.width)``
    triangles (``golden_model.fixed.engine.prepare``: the exact sum fits int64).
    """
    triangle_bits = MAX_PRODUCT_WIDTH - fs.face_area.width
    return data.StructLayout({
        "face_edge": unsigned(triangle_bits + 2),
        "face_area": unsigned(triangle_bits),
        "area_sum": unsigned(1),
    })


def normalise_layout(fs: FormatSet) -> data.StructLayout:
    """A sum to normalise: ``sum`` [error_acc] and the host's reciprocal of the total,
    ``mantissa`` [reciprocal] and ``shift`` (``sum/total ≈ sum·mantissa·2^-shift``,
    :class:`~golden_model.fixed.measures.Reciprocal`). ``shift`` holds the shift of every total
    below ``2**MAX_PRODUCT_WIDTH`` (``reciprocal.width + 62`` at most)."""
    return data.StructLayout({
        "sum": shape_of(fs.error_acc),
        "mantissa": shape_of(fs.reciprocal),
        "shift": unsigned((fs.reciprocal.width + MAX_PRODUCT_WIDTH).bit_length()),
    })


def energy_sums_layout(fs: FormatSet, entries_capacity: int) -> data.StructLayout:
    """The exact sums of one force pass over at most ``entries_capacity`` entries:
    ``square_sum`` Σe² (``e = |L − d|`` [rest_length], squared: raw at twice its fraction bits),
    ``barrier_sum`` Σc·h ([barrier_coeff]·[area], ``h ≥ 0``), and ``first``: the run's first
    pass (its energy has no predecessor)."""
    square_max = entries_capacity * fs.rest_length.raw_max ** 2
    barrier_max = entries_capacity * fs.barrier_coeff.raw_max * fs.area.raw_max
    return data.StructLayout({
        "square_sum": unsigned(square_max.bit_length()),
        "barrier_sum": unsigned(barrier_max.bit_length()),
        "first": unsigned(1),
    })


#: The exact sums the passes hand the controller (:func:`pass_sum_shapes`), in the order the engine wires them.
PASS_SUMS = ("length_sum", "square_sum", "barrier_sum", "power_sum")


def pass_sum_shapes(fs: FormatSet, vertices_capacity: int, entries_capacity: int) -> dict[str, ShapeCastable]:
    """The shapes of the exact sums the passes hand the controller, each wide enough for a pass over
    ``vertices_capacity`` nodes and ``entries_capacity`` entries: ``length_sum`` Σ|L − d| (a node's
    [error_acc] term per node), ``square_sum`` and ``barrier_sum`` (:func:`energy_sums_layout`),
    ``power_sum`` S = ΣF·V (signed, a node's [power] term per node)."""
    node_bits = vertices_capacity.bit_length()
    sums = energy_sums_layout(fs, entries_capacity)
    shapes = {"length_sum": unsigned(fs.error_acc.width + node_bits),
              "square_sum": sums["square_sum"].shape, "barrier_sum": sums["barrier_sum"].shape,
              "power_sum": signed(fs.power.width + node_bits)}
    return {name: shapes[name] for name in PASS_SUMS}


def energy_result_layout(energy_bits: int) -> data.StructLayout:
    """``energy`` (``energy_raw``: three times the energy, exact, ``energy_bits`` wide) and
    ``settled``: the stopping rule's relative energy change is within ε."""
    return data.StructLayout({"energy": unsigned(energy_bits), "settled": unsigned(1)})


# ---------------------------------------------------------------- the engine's memory words (hdl/engine.py)

def word_layout(layout: MemoryLayout) -> data.StructLayout:
    """A memory word of the map as a ``lib.data`` layout: the same fields in the same order (LSB first)."""
    return data.StructLayout({f.name: (signed if f.signed else unsigned)(f.width) for f in layout.fields})


def weight_word_layout(fs: FormatSet) -> data.StructLayout:
    """A word of the engine's weight memory: the node's ``1/m`` and its barrier weight [inv_mass]."""
    return data.StructLayout({"inv_mass": shape_of(fs.inv_mass), "inv_mass_barrier": shape_of(fs.inv_mass)})


def force_word_layout(fs: FormatSet) -> data.StructLayout:
    """A word of the engine's force memory: a node's force [force_acc] and ``inside`` (the barrier's flag)."""
    return data.StructLayout({"force": vector_layout(fs.force_acc), "inside": unsigned(1)})
