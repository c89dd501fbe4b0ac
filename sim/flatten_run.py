"""One flattening as ``springflat flatten`` runs it: the engine chosen, the run, the one-line result, the JSON
summary and the output files.

``sim/cli.py`` (the command) and ``sim/batch.py`` (many meshes, each in a worker) both run a mesh
through here."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from golden_model.fixed.engine import check_fixed_params, prepare, presets_holding, scale_mesh
from golden_model.fixed.formats_set import FORMAT_FIELDS, FormatSet
from golden_model.fixed.measures import ERROR_MEASURE_EVENTS, FixedPointError
from golden_model.guard import SCALE_MAX_SHIFT, energy_floor_strain
from golden_model.mesh import Mesh, loop_length, overlap_counts, signed_areas_2d
from golden_model.modes import Step
from golden_model.params import FlattenParams
from golden_model.reference import RUNAWAY_FACTOR, energy_floor
from golden_model.results import FlattenResult

from .distortion import distortion, worst_summary, write_distortion_csv
from .engines import DEFAULT_ENGINE, ENGINES, SERIAL_ENGINE_NAMES, Engine, engine_named
from .mesh_io.polygons import plural
from .outputs import OutputWriteError, all_or_nothing, print_note, progress_bar, write_history, write_plot
from .patterns import (DEFAULT_PAPER, PATTERN_SUFFIXES, TRUE_SCALE_KINDS, PatternDrawing, check_grain,
                       check_mesh_fits, check_seam_fits, cut_file_notes, error_text, kind_or_none, on_sheets,
                       run_caption, seam_length, write_pattern_file)
from .run_options import UserError, check_float_start, default_init, init_notes, load_format_set, start_positions
from .workers import local_workers

#: ``flatten``'s output options: ``(argparse dest, flag, the file endings it takes)``. ``--out`` may be given
#: several times; in a batch each value is an ending (``--out .pdf``) appended to each mesh's name.
OUTPUT_OPTIONS = (("out", "--out", PATTERN_SUFFIXES), ("history", "--history", (".csv",)),
                  ("plot", "--plot", (".png",)), ("distortion", "--distortion", (".csv",)))


def output_paths(args: argparse.Namespace) -> list[tuple[str, str, tuple[str, ...], Path]]:
    """``(dest, flag, endings it takes, path)`` of every output given to ``flatten`` (``--out`` once per value)."""
    paths = []
    for dest, flag, endings in OUTPUT_OPTIONS:
        value = getattr(args, dest, None)
        for path in (value or []) if dest == "out" else ([] if value is None else [value]):
            paths.append((dest, flag, endings, path))
    return paths


def check_print_size(args: argparse.Namespace, mesh: Mesh) -> None:
    """A PDF or SVG that could only be refused after the run is refused before it (a wrong --units), and a
    ``--grain`` normal to the whole surface, and a seam allowance longer than half the mesh's edge."""
    seam = 0.0 if args.seam_allowance is None else seam_length(args.seam_allowance, args.units)
    if seam:  # the 3D edge's length: the pattern's, to its strain (the drawing checks the longer of the two)
        check_seam_fits(seam, loop_length(mesh.vertices[mesh.boundary_loop]), args.units)
    if any(on_sheets(path) for path in args.out or ()):
        check_mesh_fits(mesh, args.units, paper_of(args), seam)
    if args.grain is not None:
        check_grain(mesh, args.grain)


def paper_of(args: argparse.Namespace) -> str:
    """The sheet of the run's PDF and SVG patterns: ``--paper``, or :data:`~sim.patterns.DEFAULT_PAPER`."""
    return args.paper or DEFAULT_PAPER


def check_formats_option(args: argparse.Namespace) -> None:
    """``--formats`` belongs to the fixed-point engines."""
    if not engine_named(args.engine).fixed_point and args.formats is not None:
        raise UserError("--formats applies to the fixed-point engines: --engine "
                        + ", ".join(e.name for e in ENGINES if e.fixed_point))


def check_options_used(args: argparse.Namespace) -> None:
    """Refuse, before any run, an option of ``flatten`` that this run (or batch: ``--out`` then holds
    endings) would ignore, in one line naming what it needs."""
    check_formats_option(args)
    if args.dxf_edges and not any(kind_or_none(path) == "dxf" for path in args.out or ()):
        raise UserError("--dxf-edges draws the mesh's edges into a DXF pattern: add --out NAME.dxf")
    if args.grain is not None and not args.out:
        raise UserError("--grain turns the pattern files and draws their grain line: add --out NAME.dxf, .pdf, .svg, "
                        ".obj or .flat.obj")
    if args.seam_allowance is not None and not any(kind_or_none(path) in TRUE_SCALE_KINDS for path in args.out or ()):
        raise UserError("--seam-allowance draws the cut line outside the pattern's edge: add a .dxf, .pdf or .svg "
                        "--out")
    if args.skip_existing and args.out_dir is None:
        raise UserError("--skip-existing skips a batch's meshes whose files are in --out-dir: add --out-dir DIR")
    if args.paper is not None and not any(on_sheets(path) for path in args.out or ()):
        raise UserError("--paper is the sheet of a PDF or SVG pattern: add --out NAME.pdf or NAME.svg (a .flat.svg is "
                        "the layout drawn to fit, not a pattern on sheets)")
    for option, what in (("port", "the serial port"), ("baud", "the serial port's rate")):
        if getattr(args, option) is not None and not engine_named(args.engine).serial:
            serial = " or ".join(SERIAL_ENGINE_NAMES)
            if args.more_meshes or args.out_dir is not None or args.scheduler is not None:  # a batch
                raise UserError(f"--{option} sets {what} of --engine {serial}, which runs one mesh at a time: drop "
                                f"--{option} for a batch")
            raise UserError(f"--{option} sets {what}: add --engine {serial}" if args.engine == DEFAULT_ENGINE else
                            f"--{option} sets {what} of --engine {serial}, not of --engine {args.engine}: drop "
                            f"--{option}, or run --engine {serial}")
    if args.jobs is not None:
        local_workers(args.jobs, "--jobs")


def choose_engine(args: argparse.Namespace, params: FlattenParams, mesh: Mesh):
    """The run ``--engine`` and ``--formats`` name, ``run(mesh, P0, params, on_iteration=None)``, once
    the checks of what its formats and the engine cannot run have passed: the parameters', and the mesh's
    whatever its layout (:func:`check_engine_holds`), before any layout work."""
    engine = engine_named(args.engine)
    check_formats_option(args)
    formats = run_formats(args)
    if engine.fixed_point:
        check_fixed_params(params, formats)
    if engine.hardware:
        from golden_model.engine_spec.image import check_engine_params, check_run_limits

        # (the rtl engine is built with the coarse space the run asks for; the board's is checked once it is read)
        check_engine_params(params)
        check_run_limits(params)
    check_engine_holds(engine, formats, mesh, params)
    run = engine.make(args, formats)
    return _naming_presets_that_hold(run, formats) if engine.fixed_point else run


def _naming_presets_that_hold(run, formats):
    """``run``, whose refusal of a problem its format set cannot hold names the presets that hold it."""
    def hinted(mesh, positions, params, **kw):
        try:
            return run(mesh, positions, params, **kw)
        except FixedPointError as exc:
            if _holds(mesh, positions, params, formats):  # refused for something else (the engine's capacity)
                raise
            raise _with_presets_hint(exc, presets_holding(mesh, positions, params)) from None
    return hinted


def _with_presets_hint(exc: FixedPointError, holding: list[str]) -> FixedPointError:
    """``exc``, naming the presets in ``holding`` (those that hold what it refused), if any."""
    if not holding:
        return exc
    hint = (f"the preset {holding[0]} holds it: --formats {holding[0]}" if len(holding) == 1 else
            f"the presets {', '.join(holding)} hold it: --formats {' or '.join(holding)}")
    return FixedPointError(f"{exc}; {hint}")


def check_engine_holds(engine: Engine, formats: FormatSet | None, mesh: Mesh, params: FlattenParams) -> None:
    """Refuse a mesh that ``engine`` and its ``formats`` cannot hold whatever its layout: a node's degree, its
    edge lengths or weights in the formats (one line naming the presets that hold the mesh), the engine's
    capacity. What depends on the layout (its extent) is checked when the run starts."""
    if not engine.fixed_point:
        return
    try:
        scale_mesh(mesh, params, formats)
    except FixedPointError as exc:
        raise _with_presets_hint(exc, presets_holding(mesh, None, params)) from None
    if engine.check_mesh is not None:
        engine.check_mesh(mesh)


def _holds(mesh: Mesh, positions, params: FlattenParams, formats) -> bool:
    try:
        prepare(mesh, positions, params, formats)
    except FixedPointError:
        return False
    return True


def run_formats(args: argparse.Namespace):
    """The format set a run of ``args`` uses (``--formats``, or the default set), ``None`` for a float run."""
    if not engine_named(args.engine).fixed_point:
        return None
    return load_format_set("default" if args.formats is None else args.formats)


def run_flatten(args: argparse.Namespace, mesh: Mesh, params: FlattenParams, progress: bool = False,
                second_core: bool = False, notes: list[str] | None = None) -> FlattenResult:
    """One flattening as ``args`` asks (initial layout, engine); sets ``args.init`` to the layout used.

    What the formats or the engine cannot run is refused before any layout work; a guarded run starts
    fold-free where that can be had (:func:`~sim.run_options.start_positions`; ``second_core``: SLIM may run beside
    ARAP; ``notes``: where its notes go instead of stderr)."""
    if args.init is None:
        args.init = default_init(args.mesh)
    engine = choose_engine(args, params, mesh)
    for note in init_notes(args.mesh, args.init):
        if notes is not None:
            notes.append(note)
        else:
            print_note(note)
    positions, args.init = start_positions(mesh, args.init, params, notes is None and sys.stderr.isatty(), second_core,
                                           notes)
    if not engine_named(args.engine).fixed_point:
        check_float_start(mesh, positions, params, args.init)
    # the engines test every state for finiteness themselves (status "diverged"): no numpy warnings on the way
    with progress_bar(params.max_iter, progress, label="flattening") as bar, np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        result = engine(mesh, positions, params, on_iteration=lambda k, m: bar.update(1))
    # counted on a fold-free pattern, where it is the question left (and the boundary cannot be tangled)
    if result.status != "diverged" and not result.final.folded:
        crossings, turned = overlap_counts(result.positions, mesh.faces, mesh.boundary_loops)
        result.extra["boundary_crossings"] = crossings
        if turned is not None:
            result.extra["turned_holes"] = turned
    return result


def overlap_count(summary: dict) -> int | None:
    """The pattern's overlaps (``summary``: a run's ``--json`` summary or ``extra``): pairs of its boundary's sides
    that meet and kept holes it wraps over, 0 where a cut along the boundary gives the piece; ``None`` where not
    counted (a folded or diverged pattern)."""
    crossings = summary.get("boundary_crossings")
    return None if crossings is None else crossings + (summary.get("turned_holes") or 0)


def overlap_note(result: FlattenResult) -> str | None:
    """A pattern whose boundary crosses itself, or that wraps over a kept hole: flaps lie on each other, though
    no triangle need be folded (the guard keeps triangles from folding, not distant parts of the pattern from
    meeting)."""
    crossings = result.extra.get("boundary_crossings")
    turned = result.extra.get("turned_holes")
    if not crossings and not turned:
        return None
    what = []
    if crossings:
        what.append(f"{crossings} pair{'s' if crossings > 1 else ''} of its boundary's sides meet")
    if turned:
        what.append(f"it wraps over {turned} of its holes, covering {'them' if turned > 1 else 'it'} twice")
    return (f"the pattern overlaps itself, though no triangle is folded: {' and '.join(what)}; parts of the pattern "
            "lie on each other, and a cut along the boundary does not give the piece; springflat keeps triangles "
            "from folding, not parts of the pattern from overlapping (docs/guard.md)")


def _guard_on(params: FlattenParams, api: bool = False) -> str:
    """The options that give an unguarded run the step guard, followed literally: the guard refuses the
    penalty, and the momentum dynamics the paper dynamics' own options (``api``: the API's keywords)."""
    if not params.mode.has_masses:  # the momentum dynamics, unguarded
        if api:
            return "guard=True" + (", penalty=False and no penalty_gain or penalty_kappa" if params.penalty else "")
        return "drop --no-guard" + (", --penalty, --penalty-gain and --penalty-kappa" if params.penalty else "")
    penalty = ""
    if params.penalty:
        penalty = (" without penalty, penalty_gain or penalty_kappa" if api
                   else " without --penalty, --penalty-gain or --penalty-kappa")
    return (("dynamics='momentum'" if api else "--dynamics momentum") + penalty + " (it takes none of "
            + ("step, dt, damping, density" if api else "--step, --dt, --damping, --density") + ")")


def _option(name: str, value: object = None, api: bool = False) -> str:
    """An option as the command line spells it (``--penalty-gain 2``) or the API's keyword (``penalty_gain=2``)."""
    if api:
        return name if value is None else f"{name}={value!r}"
    return f"--{name.replace('_', '-')}" + ("" if value is None else f" {value}")


def divergence_hint(params: FlattenParams, api: bool = False) -> str:
    """What to try after a diverged run, naming only options its mode takes (``api``: the API's keywords). A
    guarded run's energy never rises, so only numbers at the ends of their ranges overflow it (a spring
    constant of 1e300 on a mesh 1e45 across)."""
    mode = params.mode
    if mode.guarded:
        return f"the guarded run's numbers overflowed: bring {_option('spring', api=api)} or the mesh's size nearer 1"
    smaller = f"{_option('penalty_gain', api=api)} than {params.penalty_gain:g}" + (  # kappa, where the user raised it
        f" or {_option('penalty_kappa', api=api)} than {params.penalty_kappa:g}"
        if params.penalty_kappa > FlattenParams.penalty_kappa else "")
    penalty = (f"the overlap penalty pushes nodes apart unchecked: try a smaller {smaller}, or drop "
               f"{_option('penalty', api=api)}; " if params.penalty else "")
    if not mode.has_masses:
        return (penalty + f"the momentum dynamics without its guard: {_guard_on(params, api)}"
                + f"; with {_option('spring', api=api)} or the mesh's size far from 1 a guarded run overflows too")
    dt = _option("dt", api=api)
    step = f"a smaller {dt}" if mode.step is Step.FIXED else f"{_option('step', 'fixed', api)} with a small {dt}"
    damping = (f"a larger {_option('damping', api=api)} than {params.damping:g}" if params.damping >= DIVERGENCE_DAMPING
               else _option("damping", DIVERGENCE_DAMPING, api))
    stiffer = (f"a smaller {_option('spring', api=api)} than {params.spring:g} (it scales every force), "
               if params.spring > FlattenParams.spring else "")  # (where the user raised it)
    return penalty + f"the paper dynamics has no guard: try {stiffer}{damping}, {step}, or {_guard_on(params, api)}"


#: The damping :func:`divergence_hint` suggests to an undamped paper run.
DIVERGENCE_DAMPING = 0.05


def divergence_note(params: FlattenParams, result: FlattenResult, api: bool = False) -> str | None:
    """Where a diverged run ran away, what that means, and what to try (:func:`divergence_hint`; ``api``: in
    the API's keywords)."""
    if result.status != "diverged":
        return None
    last = f"iteration {result.iterations}" if result.iterations else "the start"
    return (f"iteration {result.iterations + 1} ran away: {RAN_AWAY} ({divergence_hint(params, api)}); the results "
            f"are of {last}, the last finite layout")


def fold_note(params: FlattenParams, result: FlattenResult, api: bool = False) -> str | None:
    """A pattern that ends with folded triangles (not diverged): it is no piece to cut as it is; what keeps
    triangles from folding, in the command line's words or (``api``) the Python API's."""
    folded = result.final.folded
    if result.status == "diverged" or not folded:
        return None
    if params.mode.guarded:
        why = ("the step guard adds no fold, but keeps those of its start (untangling could not remove them; "
               "docs/guard.md)")
    elif not params.mode.has_masses:
        why = f"the step guard keeps every triangle from folding: {_guard_on(params, api)}; docs/guard.md"
    else:
        barrier = ", nor does its fold barrier, a force that only pushes back" if params.barrier else ""
        why = (f"the paper dynamics does not keep triangles from folding{barrier}; the momentum dynamics with its step "
               f"guard does: {_guard_on(params, api)}; docs/guard.md")
    return (f"the pattern has {folded} folded triangle{'s' if folded > 1 else ''}, flipped over their neighbours: "
            f"cut along its boundary it is not the mesh's piece; {why}")


def growth_note(params: FlattenParams, result: FlattenResult, api: bool = False) -> str | None:
    """A layout that grew away from the mesh (E_S above 1: its area off by more than the mesh's own) without
    tripping the runaway rule (``RUNAWAY_FACTOR`` times wider): no pattern to cut, though the run ended."""
    initial, final = result.initial.area_error, result.final.area_error
    if result.status == "diverged" or not final > max(1.0, initial):
        return None
    return (f"the layout grew away from the mesh: E_S {error_text(initial)} -> {error_text(final)}, its area off by "
            f"{final:.3g} times the mesh's: no pattern to cut, though it stayed under the runaway rule's "
            f"{RUNAWAY_FACTOR:g} times" + ("" if api else f"; {divergence_hint(params)}"))


#: A pattern whose area is below this share of its surface's is said to be shrunk (:func:`shrink_note`): the
#: counterpart of :func:`growth_note`'s E_S above 1, which a pattern grown everywhere passes at twice the area.
SHRUNK_AREA_SHARE = 0.5


def shrink_note(mesh: Mesh, result: FlattenResult) -> str | None:
    """A pattern whose area is below :data:`SHRUNK_AREA_SHARE` of its surface's: a patch too curved to lie flat at
    its size (a cap folded like a taco), whose springs' minimum shrinks it. E_S, the triangles' area changes over
    the surface's area, is at most 1 for a shrunk pattern however small, so the growth note's E_S above 1 never
    sees one."""
    if result.status == "diverged":
        return None
    share = float(np.abs(signed_areas_2d(result.positions, mesh.faces)).sum() / mesh.face_areas.sum())
    if not share < SHRUNK_AREA_SHARE:
        return None
    return (f"the pattern's area is {share:.0%} of the surface's (E_S {error_text(result.final.area_error)}): the "
            "patch is too curved to lie flat at its own size, and the pattern is that much smaller; pieces cut "
            "from it (a seam, darts) each lie flatter")


def saturation_note(params: FlattenParams, result: FlattenResult, formats: FormatSet | None,
                    api: bool = False) -> str | None:
    """A fixed-point run (of format set ``formats``) that clamped values: which, and where wider formats are;
    one that ran away to the top of its formats: what to try instead (wider formats only move the top).
    ``api``: in the Python API's words."""
    events = result.extra.get("saturation_events") or {}
    if not result.extra.get("saturations"):
        return None
    fields = ", ".join(f"{name} {count}" for name, count in sorted(events.items(), key=lambda item: -item[1])[:3])
    note = (f"format set '{result.extra['formats']}' clamped {result.extra['saturations']} values to its range"
            + (f" ({fields})" if fields else "") + ", which moves the result away from the float reference's")
    final = result.final
    if max(final.area_error, final.shape_error) >= formats.error.max:  # E_S, E_C clamped: no flattening
        return (note + "; E_S or E_C is at the top of its format: the run ran away (the float engine calls such a "
                "run diverged), and the pattern is no flattening" + ("" if api else f"; {divergence_hint(params)}"))
    if set(events) <= set(ERROR_MEASURE_EVENTS):  # layouts of E 1 or more (far from flat): step and stop take E as 1
        return (f"format set '{result.extra['formats']}' held {result.extra['saturations']} E_S/E_C measures of 1 or "
                f"more at the top of its error format ({formats.error}): no step or stop rule tells them from 1, so "
                "the run is not moved by them, but --history records such a layout's E_S or E_C as "
                f"{formats.error.max:.6g}")
    wider = [name for name in FormatSet.presets() if _holds_more(FormatSet.preset(name), formats, events)]
    return (note + (f"; a format set with more integer bits holds them (presets: {', '.join(wider)}; "
                    "docs/fixed-point.md)" if wider else "; no preset has more integer bits there: a "
                    + ("formats=FILE" if api else "--formats FILE") + " can (docs/fixed-point.md)"))


def _holds_more(candidate: FormatSet, formats: FormatSet, clamped: dict[str, int]) -> bool:
    """Whether ``candidate`` has more integer bits than ``formats`` where values were clamped: at least as
    many in each clamped signal that is a format and more in one (or, where none is, in every format at
    least as many and more in one)."""
    signals = [name for name in FORMAT_FIELDS if name in clamped] or list(FORMAT_FIELDS)
    pairs = [(getattr(candidate, name).int_bits, getattr(formats, name).int_bits) for name in signals]
    return all(mine >= theirs for mine, theirs in pairs) and any(mine > theirs for mine, theirs in pairs)


def pattern_notes(params: FlattenParams, mesh: Mesh, result: FlattenResult, api: bool = False,
                  formats: FormatSet | None = None) -> list[str]:
    """What a person must know about a pattern of ``mesh`` before cutting it: grown away, shrunk, folded,
    overlapping, or (a fixed-point run of ``formats``) clamped, at the top of its format where it ran away."""
    return [note for note in (growth_note(params, result, api), shrink_note(mesh, result),
                              fold_note(params, result, api), overlap_note(result),
                              saturation_note(params, result, formats, api), still_note(params, result, formats, api),
                              coarse_note(formats))
            if note]


def coarse_note(formats: FormatSet | None) -> str | None:
    """A fixed-point run of a format set so coarse that its documented bound against float (``accuracy_bound``,
    docs/fixed-point.md) is 1 or more: E_S and E_C are at most 1, so the bound promises nothing."""
    if formats is None or formats.accuracy_bound() < 1:
        return None
    return (f"format set '{formats.name}' is so coarse that its accuracy bound against the float engine is "
            f"{formats.accuracy_bound():.3g}, which promises nothing for E_S and E_C: compare with the float engine "
            "(docs/fixed-point.md)")


#: E_S and E_C below which a start is a flattening already (a flat patch, its errors the formats' rounding):
#: :func:`still_note` says nothing of a run that left it as it was.
STILL_START_ERROR = 1e-4


def still_note(params: FlattenParams, result: FlattenResult, formats: FormatSet | None,
               api: bool = False) -> str | None:
    """A run of the paper dynamics whose pattern is its start though it 'converged': a fixed-point run (of
    ``formats``) that stopped with the energy it started with, to the bit, a nonzero one (from rest its first
    moves, ½Δt²·F/m, rounded to no move, so the relative energy change was 0 and the stop rule held while the
    float run may go on), or a float run that stopped after its first step (:func:`_still_float_note`). The
    run's words are true (the layout no longer changes) but the pattern is its start. (The momentum dynamics
    does not start from rest; a start whose E_S and E_C are below :data:`STILL_START_ERROR` is a flattening
    already.)"""
    energy = np.asarray(result.history.energy)
    if (not params.mode.has_masses or result.status != "converged" or len(energy) < 2
            or max(result.initial.area_error, result.initial.shape_error) < STILL_START_ERROR):
        return None
    if formats is None:
        return _still_float_note(params, result, energy, api)
    if not np.all(energy == energy[0]):
        return None
    float_engine = "engine='float'" if api else "--engine float"
    return (f"the run stopped without changing the layout's energy: its steps round to no move in the "
            f"{formats.position.frac_bits} fraction bits of the positions (format set '{formats.name}'), so the "
            f"stop rule held at once, and the pattern is its start; the float engine, whose steps are not rounded, "
            f"may move it ({float_engine}), if slowly where E_S and E_C are small; the momentum dynamics does not "
            f"start from rest: {_guard_on(params, api)}")


def _still_float_note(params: FlattenParams, result: FlattenResult, energy: np.ndarray, api: bool) -> str | None:
    """:func:`still_note` of the float engine: a run of the paper dynamics that stopped after its first step,
    whose relative energy change was within ε. From rest that step (½Δt²·F/m) is the run's smallest, so the
    stop rule held before the layout moved more than a trace (a tiny ``Δt``, a huge density)."""
    if result.iterations != 1 or not energy[0] > 0:
        return None
    change = abs(energy[1] - energy[0]) / energy[0]
    larger = "a larger dt with step='fixed'" if api else "a larger --dt with --step fixed"
    if params.density != "auto":  # heavy nodes: their moves are F/m
        larger += " and a smaller density" if api else " and a smaller --density"
    if change > 0:  # (a change of 0 meets any tolerance)
        larger += ", or a smaller tol_energy" if api else ", or a smaller --tol-energy"
    step = ("which left the layout's energy as it was" if change == 0 else
            f"which changed the layout's energy by a relative {change:.2g}, within the stop rule's "
            f"{params.tol_energy:g}")
    return (f"the run stopped after its first step, {step}: from rest the paper dynamics' first step is its "
            f"smallest, and the pattern is its start, barely moved; larger steps move it: {larger}; the momentum "
            f"dynamics does not start from rest: {_guard_on(params, api)}")


def json_summary(args: argparse.Namespace, mesh: Mesh, params: FlattenParams, result: FlattenResult) -> dict:
    """What ``--json`` prints: the mesh (its kept holes, the cut-outs), the run's summary, the distortion's worst
    1 %, what was used (and the seam allowance of the pattern files, in ``units``, where one is asked for)."""
    seam = {} if args.seam_allowance is None else {"seam_allowance": seam_length(args.seam_allowance, args.units)}
    return {"mesh": mesh.name, "vertices": mesh.n_vertices, "faces": mesh.n_faces, "holes": mesh.n_holes,
            "init": args.init,
            **result.summary(), "units": args.units, **seam,
            "distortion": worst_summary(distortion(mesh, result.positions)),
            "used": what_was_used(params, args.init, result, mesh)[len("springflat: "):]}


def human_line(mesh: Mesh, result: FlattenResult) -> str:
    """The one-line result a person reads."""
    final = result.final
    return (f"{mesh.name}: {result.status} after {plural(result.iterations, 'iteration')}: "
            f"E_S {error_text(result.initial.area_error)} -> {error_text(final.area_error)}, "
            f"E_C {error_text(result.initial.shape_error)} -> {error_text(final.shape_error)}, "
            f"folded {final.folded} (flipped against P0: {final.flipped})"
            + (f", overlaps {overlaps}" if (overlaps := overlap_count(result.extra)) else "")
            + (f", {result.extra['saturations']} saturation events" if "saturations" in result.extra else "")
            + (f"; {result.extra['cycles']} engine cycles on {result.extra['simulator']}"
               if "simulator" in result.extra else ""))


def what_was_used(params: FlattenParams, init: str, result: FlattenResult, mesh: Mesh) -> str:
    """One line: dynamics, initial layout, stop rule (with the energy floor where the mode has one), and why
    the run stopped."""
    barrier = (f", fold barrier (kappa {params.barrier_threshold:g}, mu {params.barrier_gain:g})" if params.barrier
               else "")
    penalty = ", overlap penalty" if params.penalty else ""
    if params.mode.step is Step.MOMENTUM:
        dynamics = ("momentum dynamics, " + ("step guard" if params.guard else "no step guard")
                    + (f", coarse space of degree {params.coarse_degree}" if params.coarse_degree else "")
                    + (barrier or ", no barrier") + penalty)
    else:
        dynamics = (f"paper dynamics, {params.step} step" + (f", damping {params.damping:g}" if params.damping else "")
                    + barrier + penalty)
    rule = f"relative energy change <= {params.tol_energy:g}" + (
        f" over {params.energy_window} iterations" if params.energy_window > 1 else "")
    floor = energy_floor(mesh, params)
    strain = energy_floor_strain(params.tol_energy)
    if floor > 0:
        rule += f", or an energy below the floor of an rms edge strain of {strain:g}"
    if params.tol_area < 1 or params.tol_shape < 1:
        rule = f"E_S <= {params.tol_area:g}, E_C <= {params.tol_shape:g} and {rule}"
    below = result.final.energy < floor
    if params.tol_area < 1 or params.tol_shape < 1:  # all three held: the energy's may have held long before
        held = ("E_S and E_C within their tolerances, and the energy " + ("below the floor" if below else
                                                                         "rule held"))
    else:
        held = "the energy fell below the floor (a smaller --tol-energy lowers it)" if below else "the stop rule held"
    why = {"converged": held, "max-iterations": f"N_max = {params.max_iter} reached",
           "diverged": RAN_AWAY,
           "stalled": "no step lowered the energy any more (the guard's step scale fell below "
                      f"2^-{SCALE_MAX_SHIFT}); the pattern is the last accepted, fold-free layout"}[result.status]
    return f"springflat: used {dynamics}, initial layout {init}; stop rule: {rule}; stopped: {why}"


def notes_on_cut_files(args: argparse.Namespace, mesh: Mesh, result: FlattenResult,
                       drawing: PatternDrawing) -> list[str]:
    """The notes on a run that writes a pattern at 1:1 (a print or a cut; ``vt`` and layouts have no scale):
    :func:`~sim.patterns.cut_file_notes` of ``drawing``, the files' own (:func:`pattern_drawing`)."""
    if result.status == "diverged" or not any(kind_or_none(path) in TRUE_SCALE_KINDS for path in args.out or ()):
        return []
    return cut_file_notes(drawing)


#: What a diverged float run did (:func:`golden_model.reference.runaway_width`).
RAN_AWAY = (f"a value stopped being finite, or the layout grew {RUNAWAY_FACTOR:g} times wider than the mesh's "
            "edges laid end to end")

#: The outputs a diverged run does not write: its last finite layout is no pattern, and a non-zero exit must
#: not leave a fresh target (an existing file is kept). ``--history`` and ``--plot`` show the divergence.
PATTERN_OUTPUTS = ("--out", "--distortion")


def pattern_drawing(args: argparse.Namespace, mesh: Mesh, result: FlattenResult) -> PatternDrawing:
    """The drawing the pattern files are written from: the layout with the run's caption, turned as the mesh is
    seen from its front, or to ``--grain``, and with ``--seam-allowance`` (neither for a diverged run)."""
    final = result.final
    drawing = PatternDrawing.of(mesh, result.positions, args.units, run_caption(
        result.status, result.iterations, final.area_error, final.shape_error, final.folded,
        result.extra.get("boundary_crossings"), result.extra.get("turned_holes"))).as_seen()
    if args.grain is not None and args.out and result.status != "diverged":
        drawing = drawing.with_grain(args.grain)
    if args.seam_allowance is not None and result.status != "diverged":
        drawing = drawing.with_seam(seam_length(args.seam_allowance, args.units))
    return drawing


def write_outputs(args: argparse.Namespace, mesh: Mesh, result: FlattenResult, drawing: PatternDrawing) -> list[Path]:
    """Write the outputs asked for, the pattern files from ``drawing`` (:func:`pattern_drawing`): all of them, or
    (on an error) none; a diverged run's only those that are not :data:`PATTERN_OUTPUTS`. The paths written."""
    title = f"{mesh.name} ({result.engine} engine)"
    jobs = [(path, "--out", lambda path: write_pattern_file(path, drawing, paper=paper_of(args),
                                                            dxf_edges=args.dxf_edges))
            for path in args.out or ()]
    jobs += [(args.history, "--history", lambda path: write_history(path, result)),
             (args.plot, "--plot", lambda path: write_plot(path, result, mesh.faces, title=title,
                                                           vertices=mesh.vertices, turn=drawing.turn)),
             (args.distortion, "--distortion",
              lambda path: write_distortion_csv(path, distortion(mesh, result.positions), args.units))]
    written = []
    try:
        with all_or_nothing():
            for path, what, write in jobs:
                if path is None or (result.status == "diverged" and what in PATTERN_OUTPUTS):
                    continue
                written.append(path)
                try:
                    write(path)
                except OutputWriteError as exc:
                    raise OutputWriteError(exc.path, exc.error, what) from None
                except OSError as exc:
                    raise OutputWriteError(path, exc, what) from None
    except OutputWriteError as exc:  # one that failed as they were put in place: named by its option
        if exc.what:
            raise
        named = next((what for path, what, _ in jobs if path == exc.path), "")
        raise OutputWriteError(exc.path, exc.error, named, exc.left) from None
    return written
