"""The library face of springflat: :func:`read_mesh`, :func:`flatten`, :func:`write_pattern`.

One definition of the options.  ``springflat flatten``'s run options are defined once, by
:func:`sim.run_options.add_run_options` and :func:`sim.cli.add_engine_options`.  This module calls
those two functions on a recorder (:class:`_Recorder`) instead of a parser, which yields
:data:`OPTIONS`: every keyword :func:`flatten` takes, with the flag, type, choices and help text of the
command line.  A keyword's value goes through the option's own argparse ``type`` (given as text, so
``max_iter=2.5`` is refused as the command line refuses ``--max-iter 2.5``) and ``choices``; the
namespace then goes through :func:`sim.run_options.params_from_args` like the command line's, which
checks each value's domain (:class:`golden_model.params.ParameterError`).  A new option of the
command line is a new keyword here with no edit.

One set of defaults.  Arrays get the defaults of a mesh *file* (:func:`sim.run_options.file_defaults`,
which the command takes for a file: the momentum dynamics with the fold barrier, stopped at the energy
minimum, an ARAP start): ``flatten(V, F)`` gives the layout that ``springflat flatten mesh.obj`` gives for
the same ``V``, ``F``.  A mesh named instead, ``flatten("mesh.obj")`` or a built-in's ``flatten("surf1")``,
is read as the command reads it (:func:`sim.run_options.resolve_mesh`) and gets the command's defaults for
it: a built-in the paper's parameters and its PCA start.
"""

from __future__ import annotations

import argparse
import os
import re
import warnings
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from golden_model.builtin import builtin_mesh, is_builtin
from golden_model.fixed.formats_set import FormatSet, FormatSetNotBuildable
from golden_model.fixed.measures import FixedPointError
from golden_model.mesh import HoledMesh, Holes, Mesh, MeshError, oriented_mesh
from golden_model.params import FlattenParams, ParameterError
from golden_model.results import FlattenResult
from sim.cli import add_engine_options, forget_half_built_components
from sim.distortion import Distortion, distortion
from sim.engines import ENGINES, engine_named
from sim.flatten_run import divergence_note, pattern_notes, run_flatten, run_formats
from sim.layouts import ARRAY_WORDS, AUTO_START, LAYOUT_METHODS, LayoutError, check_layout
from sim.mesh_io import load_mesh_with_notes, repair_hint
from sim.mesh_io.seams import seams_hint, seams_note
from sim.outputs import (OutputError, area_ratio, check_distinct, check_link_target, check_output_path,
                         directory_name_problem, ending_name_problem)
from sim.patterns import (DEFAULT_PAPER, TRUE_SCALE_KINDS, PatternDrawing, PatternError, add_pattern_options,
                          cut_file_notes, kind_or_none, on_sheets, pattern_ending, run_caption, seam_length,
                          write_pattern_file)
from sim.run_options import (HOLES_HINT, UserError, add_run_options, default_init, file_defaults, file_path_argument,
                             holes_mode, input_files, params_from_args, path_argument, resolve_mesh)

__all__ = ["OPTIONS", "OptionSpec", "MeshNote", "Pattern", "flatten", "read_mesh", "write_pattern"]


class MeshNote(UserWarning):
    """What :func:`read_mesh` changed or ignored in a file (polygons triangulated, STL corners merged, faces
    wound against their neighbours turned, ...), or :func:`flatten` in its arrays (faces turned) or its start
    (a folded layout untangled, SLIM's start where ARAP folds): the command's notes."""


@dataclass(frozen=True)
class OptionSpec:
    """One option of ``springflat flatten`` as :func:`flatten` takes it.

    Attributes:
        keyword: the keyword (``damping``); ``flag``: the command line's (``--damping``).
        action: argparse's action: ``None`` (takes a value), ``"store_true"`` or
            ``argparse.BooleanOptionalAction`` (a :attr:`switch`), or :class:`~sim.run_options.OneOutput` (a file).
        type: the argparse ``type`` that parses the value's text, or ``None``.
        choices: the allowed values, or ``None``.
        default: the command line's default (``None``: the mesh's default applies).
        help: the command line's help text.
    """

    keyword: str
    flag: str
    action: Any
    type: Callable[[str], Any] | None
    choices: tuple | None
    default: Any
    help: str

    @property
    def switch(self) -> bool:
        """Whether the option is a switch (``--barrier``, ``--no-barrier``) rather than one that takes a value."""
        return self.action == "store_true" or self.action is argparse.BooleanOptionalAction


class _Recorder:
    """Stands in for an ``argparse`` parser and records each option added to it."""

    def __init__(self) -> None:
        self.specs: dict[str, OptionSpec] = {}

    def add_argument(self, *names: str, **kwargs: Any) -> None:
        flags = [n for n in names if n.startswith("--")]
        if not flags:  # the positional MESH: flatten's V, F
            return
        keyword = kwargs.get("dest") or flags[0][2:].replace("-", "_")
        choices = kwargs.get("choices")
        self.specs[keyword] = OptionSpec(keyword, flags[0], kwargs.get("action"), kwargs.get("type"),
                                         None if choices is None else tuple(choices), kwargs.get("default"),
                                         " ".join(str(kwargs.get("help", "")).split()))

    def add_argument_group(self, *args: Any, **kwargs: Any) -> "_Recorder":
        return self

    add_mutually_exclusive_group = add_argument_group


def _record_options(*adders: Callable[[argparse.ArgumentParser], None]) -> Mapping[str, OptionSpec]:
    """The options the ``adders`` (``add_run_options``, ...) add to a parser, by keyword."""
    recorder = _Recorder()
    for add in adders:
        add(recorder)  # type: ignore[arg-type]
    return recorder.specs


#: Every keyword option of :func:`flatten`: the run and engine options of ``springflat flatten``.
OPTIONS: Mapping[str, OptionSpec] = _record_options(add_run_options, add_engine_options)


def _option_value(spec: OptionSpec, value: Any) -> Any:
    """``value`` checked and converted as the command line would the same text; ``None`` is the option left
    out (its default), whichever option it is."""
    if value is None:
        return spec.default
    if spec.keyword == "formats" and isinstance(value, (FormatSet, Mapping)):  # the set itself, not a file of it
        if isinstance(value, FormatSet):
            return value
        try:
            return FormatSet.from_dict(dict(value))
        except (ValueError, KeyError, TypeError) as exc:
            raise ParameterError(f"formats: {str(exc).splitlines()[0]}") from None
    if spec.keyword == "formats" and not isinstance(value, (str, os.PathLike)):  # (5 read as a preset's name)
        raise ParameterError(f"formats takes a preset's name, a JSON file's path, a FormatSet or its to_dict(), not "
                             f"a {type(value).__name__}")
    if spec.switch:
        if isinstance(value, (bool, np.bool_)):
            return bool(value)
        raise ParameterError(f"{spec.keyword} must be True or False, got {value!r}")
    if isinstance(value, (bool, np.bool_)):
        raise ParameterError(f"{spec.keyword} takes a value, not {value!r}")
    text = value if isinstance(value, str) else str(value)
    if spec.type is not None:
        try:
            value = spec.type(text)
        except (argparse.ArgumentTypeError, TypeError, ValueError) as exc:
            raise ParameterError(f"{spec.keyword}: {exc}") from None
    else:
        value = text
    if spec.choices is not None and value not in spec.choices:
        raise ParameterError(f"{spec.keyword} must be one of {', '.join(map(str, spec.choices))}, got {value!r}")
    return value


def _namespace(options: Mapping[str, Any]) -> argparse.Namespace:
    """The ``flatten`` namespace the command line would build from these keywords."""
    unknown = sorted(set(options) - set(OPTIONS))
    if unknown:
        raise TypeError(f"flatten() got unexpected keyword(s) {', '.join(unknown)}; the options are "
                        f"{', '.join(OPTIONS)}")
    values = {keyword: spec.default for keyword, spec in OPTIONS.items()}
    for keyword, value in options.items():
        values[keyword] = _option_value(OPTIONS[keyword], value)
    return argparse.Namespace(**values)


@dataclass(frozen=True, eq=False, repr=False)
class Pattern:
    """The result of :func:`flatten`. Its arrays are read-only, as its fields are frozen: its errors, its
    ``area_ratio`` and :meth:`distortion` are of those arrays (to change a layout, ``layout.copy()``).

    Attributes:
        layout: ``(V, 2)`` float64, the flat pattern, in the mesh's units; row ``i`` is vertex ``i``.
        status: ``converged``, ``max-iterations``, ``stalled`` (no step lowers the energy any more:
            ``layout`` is the last accepted one) or ``diverged`` (then ``layout`` is the last finite state).
        iterations: iterations run.
        area_error: ``E_S`` of ``layout`` (relative area error, eq. 12); for ``engine="fixed"`` the golden
            model's own sum, rounded in its formats (what the engine reports), not recomputed from ``layout``.
        shape_error: ``E_C`` of ``layout`` (relative edge-length error, eq. 14); likewise.
        folded: triangles whose orientation disagrees with the pattern's.
        boundary_crossings: pairs of the boundary's sides that meet, on a fold-free pattern (a property;
            ``None`` for a folded or diverged one): where it is not 0, parts of the pattern lie on each other.
        turned_holes: kept holes the pattern wraps over (a property; ``None`` without holes, or for a folded,
            diverged or crossing pattern): where it is not 0, the piece covers those holes twice.
        area_ratio: ``(F,)`` ``|A'_t| / A_t`` per triangle (1 = area kept).
        name: the mesh's name (printed on PDF/SVG sheets).
        vertices, faces: the mesh, ``(V, 3)`` float64 and ``(F, 3)`` int64.
        init: the initial layout used (a method name, a file, or ``"array"``).
        params: the :class:`~golden_model.params.FlattenParams` of the run.
        result: the engine's full :class:`~golden_model.results.FlattenResult` (history, velocities, ...).
        read_files: the files the run read (the mesh file, a start layout's, a format set's), absolute:
            :func:`write_pattern` writes over none of them, as the command writes no output over its inputs.
    """

    layout: np.ndarray
    status: str
    iterations: int
    area_error: float
    shape_error: float
    folded: int
    area_ratio: np.ndarray
    name: str
    vertices: np.ndarray
    faces: np.ndarray
    init: str
    params: FlattenParams
    result: FlattenResult
    read_files: tuple[Path, ...] = ()

    def __repr__(self) -> str:  # the arrays and the run's history are for their own attributes
        return (f"Pattern(name={self.name!r}, status={self.status!r}, iterations={self.iterations}, "
                f"area_error={self.area_error:.6g}, shape_error={self.shape_error:.6g}, folded={self.folded}, "
                f"{len(self.vertices)} vertices, {len(self.faces)} faces)")

    @property
    def boundary_crossings(self) -> int | None:
        """Pairs of the boundary's sides that meet: 0 for a fold-free pattern that covers no point twice;
        ``None`` where not counted (a folded or diverged pattern)."""
        return self.result.extra.get("boundary_crossings")

    @property
    def turned_holes(self) -> int | None:
        """Holes kept with ``keep_holes`` that the pattern wraps over (covers twice), on a fold-free pattern with
        holes whose boundary does not cross itself; ``None`` otherwise."""
        return self.result.extra.get("turned_holes")

    @cached_property
    def mesh(self) -> Mesh:
        """The 3D mesh as :class:`golden_model.mesh.Mesh`."""
        return Mesh(self.vertices, self.faces, name=self.name, allow_holes=True)

    def distortion(self) -> Distortion:
        """Per-triangle area ratio and per-edge strain (:class:`sim.distortion.Distortion`)."""
        return distortion(self.mesh, self.layout)

    @property
    def edge_strain(self) -> np.ndarray:
        """``(E,)`` ``l_e / d_e - 1`` per edge of ``mesh.edges``."""
        return self.distortion().strain


def read_mesh(path: str | Path, fill_holes: bool = False, keep_holes: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """``(V, F)`` of an OBJ, PLY, OFF or STL disk patch: ``(V, 3)`` float64 positions, ``(F, 3)`` int64
    vertex indices (0-based), in the file's vertex order; with ``fill_holes`` its holes are closed first
    (as ``--fill-holes``: triangles between each hole's own vertices after the file's faces; no vertex added);
    with ``keep_holes`` a disk with holes is read as it is (for ``flatten(V, F, keep_holes=True)``).

    A built-in mesh's name (``surf1``, ``surf2``) gives its arrays; note that ``flatten(V, F)`` runs arrays
    with a mesh file's defaults, and ``flatten("surf1")`` with the paper's, as the command does.

    The file must be one manifold disk (:func:`sim.mesh_io.load_mesh_with_notes`); anything else
    raises :class:`golden_model.mesh.MeshError` (a ``ValueError``) with a one-line message.  What the
    reader changed (polygons triangulated, STL corners merged) is a :class:`MeshNote` warning.
    """
    if not isinstance(path, (str, os.PathLike)):
        raise TypeError(f"read_mesh takes a file path (str or pathlib.Path), not {type(path).__name__}")
    if (problem := _nul_problem(path)) is not None:
        raise MeshError(f"cannot read mesh {problem}")
    for keyword, value in (("fill_holes", fill_holes), ("keep_holes", keep_holes)):
        if not isinstance(value, (bool, np.bool_)):
            raise TypeError(f"{keyword} must be True or False, got {value!r}")
    holes = _holes(bool(fill_holes), bool(keep_holes))
    if is_builtin(str(path)):  # (as the command reads the name; its arrays get a file's defaults in flatten)
        mesh = builtin_mesh(str(path))[0]
        return mesh.vertices, mesh.faces
    try:
        mesh, notes = load_mesh_with_notes(path, holes=holes)
    except HoledMesh as exc:
        raise MeshError(f"{exc}; {_in_api_words(HOLES_HINT)}") from None
    for note in notes:
        warnings.warn(f"{mesh.name}: {note}", MeshNote, stacklevel=2)
    return mesh.vertices, mesh.faces


def _named_mesh(path: str | os.PathLike, holes: Holes, name: str | None) -> tuple[Mesh, FlattenParams]:
    """A mesh file or a built-in, and its defaults, as the command reads it, named ``name`` where that is given;
    its notes as :class:`MeshNote`, under that name."""
    if (problem := _nul_problem(path)) is not None:
        raise MeshError(f"cannot read mesh {problem}")
    notes: list[str] = []
    try:
        mesh, defaults = resolve_mesh(os.fspath(path), holes, notes, label=name)
    except MeshError as exc:
        raise MeshError(_in_api_words(str(exc)), faces=exc.faces, vertices=exc.vertices, defect=exc.defect) from None
    if name is not None:
        mesh = Mesh(mesh.vertices, mesh.faces, name=name, allow_holes=holes is Holes.KEEP)
    for note in notes:
        warnings.warn(note, MeshNote, stacklevel=3)
    return mesh, defaults


def _holes(fill_holes: bool, keep_holes: bool) -> Holes:
    """:func:`sim.run_options.holes_mode`, its refusal in the API's words."""
    try:
        return holes_mode(fill_holes, keep_holes)
    except UserError as exc:
        raise ParameterError(_in_api_words(str(exc))) from None


def _nul_problem(path: Any) -> str | None:
    """``'path': ...`` when ``path`` holds a NUL character, which no file name can (the OS refuses it)."""
    if isinstance(path, (str, os.PathLike)) and "\0" in str(os.fspath(path)):
        return f"{str(os.fspath(path))!r}: a file name cannot hold a NUL character"
    return None


def _arrays(V: Any, F: Any) -> tuple[np.ndarray, np.ndarray]:
    if isinstance(V, (str, os.PathLike)):
        raise TypeError("flatten takes a mesh file's path (or a built-in's name) alone, or two arrays V, F")
    if F is not None and hasattr(V, "vertices") and hasattr(V, "faces"):
        raise TypeError(f"flatten takes a {type(V).__name__} alone (its faces are its own), or two arrays V, F")
    if F is None:
        if isinstance(V, (np.ndarray, list, tuple)):  # an array of vertices alone
            raise TypeError("flatten(V, F) takes the faces F too: F, the (F, 3) vertex indices, is missing")
        if not (hasattr(V, "vertices") and hasattr(V, "faces")):
            raise TypeError(f"flatten(V, F) takes two arrays, one trimesh.Trimesh, or a mesh file's path or a built-in "
                            f"mesh's name (str or pathlib.Path), not {type(V).__name__}")
        V, F = V.vertices, V.faces
    arrays = []
    for name, value, what in (("V", V, "(V, 3) vertex positions"), ("F", F, "(F, 3) vertex indices")):
        if np.ma.is_masked(value):  # np.array would take the values under the mask
            raise MeshError(f"{name} has masked entries: a mesh has no missing {what.split(') ')[1]}; fill or drop "
                            "them")
        try:
            array = np.array(value)  # a copy: the Pattern must not change when the caller's arrays do
        except ValueError:  # ragged rows (numpy's own words name its internals)
            raise MeshError(f"{name} must be an array of {what}: its rows are not all of one length") from None
        except TypeError as exc:  # objects that are no arrays
            raise MeshError(f"{name} must be an array of {what}: {str(exc).splitlines()[0]}") from None
        if array.dtype.kind not in "iuf":  # strings, complex numbers, objects, True/False: nothing to take silently
            raise MeshError(f"{name} must be an array of {what}, got {array.dtype} values")
        arrays.append(array)
    faces = arrays[1]
    if faces.dtype.kind == "f" and faces.size and np.isfinite(faces).all() and (faces == np.round(faces)).all() \
            and np.abs(faces).max() < 2**53:  # whole numbers as floats (np.loadtxt's): the indices they are
        faces = faces.astype(np.int64)
    return arrays[0], faces


def flatten(V: Any, F: Any = None, *, name: str | None = None, init: str | Path | np.ndarray | None = None,
            **options: Any) -> Pattern:
    """Flatten a triangle-mesh disk patch into a plane.

    Args:
        V: ``(V, 3)`` vertex positions (any length unit); or a ``trimesh.Trimesh``; or a mesh file's path or a
            built-in mesh's name (``"surf1"``), read as ``springflat flatten`` reads it, with its defaults
            (then no ``F``).
        F: ``(F, 3)`` 0-based vertex indices of the triangles.
        name: the mesh's name (a string), for the pattern files: by default the file's stem, or ``mesh``.
        init: the initial layout: ``auto`` (the default: ARAP, or for a guarded run SLIM from Tutte where ARAP folds or
            fails, and LSCM where that is exact, a developable patch, and more so than ARAP's),
            ``tutte``, ``pca``, ``harmonic``, ``lscm``, ``arap``, ``slim``, a layout file, or a ``(V, 2)`` array; a
            file or an array is checked (shape, finite, range), mirrored back in y where it is a mirror image of
            the mesh (clockwise, as y-down texture coordinates are), scaled to the mesh's size where it is more
            than ``sim.layouts.SIZE_TOLERANCE`` (3) times off (texture coordinates in [0, 1], say), and, with the guarded dynamics, untangled
            where it folds.
        **options: the options of ``springflat flatten`` (listed below and in :data:`OPTIONS`), the flag
            without its dashes and with ``_`` for ``-``: ``max_iter=500`` is ``--max-iter 500``.  Each value
            is checked as the command line checks the same text; ``formats`` also takes a
            :class:`~golden_model.fixed.formats_set.FormatSet` or its ``to_dict()``.  Left out (or ``None``), an
            option has the command line's default for the mesh: a mesh *file*'s for arrays
            (``springflat flatten mesh.obj``), the paper's for a built-in.

    Returns:
        a :class:`Pattern` (``.layout`` is the ``(V, 2)`` numpy array). Faces wound against their neighbours
        are turned to agree with the rest first (a :class:`MeshNote` warning says how many); ``.faces`` holds
        them so.

    Raises:
        golden_model.mesh.MeshError: ``V``, ``F`` are no arrays of numbers, or not one manifold disk (a ``ValueError``).
        golden_model.params.ParameterError: an option out of its domain, options that do not go together,
            or an ``init`` that cannot be used (a ``ValueError``).
        TypeError: an unknown keyword, or a ``name`` that is not a string.
    """
    if name is not None and not isinstance(name, str):
        raise TypeError(f"name must be a string (the mesh's name on the pattern files), not {type(name).__name__}")
    if (problem := _nul_problem(init)) is not None:
        raise ParameterError(f"init {problem}")
    named = isinstance(V, (str, os.PathLike)) and F is None
    if not named:
        vertices, faces = _arrays(V, F)
    args = _namespace(options)
    engine = engine_named(args.engine)
    if getattr(args, "formats", None) is not None and not engine.fixed_point:  # the command's check says --engine
        raise ParameterError("formats applies to the fixed-point engines: "
                             + " or ".join(f"engine={e.name!r}" for e in ENGINES if e.fixed_point and e.api))
    if not engine.api:
        raise ParameterError(f"engine {engine.name!r}, {engine.help}, runs from the command line: springflat flatten "
                             f"MESH --engine {engine.name}; the API runs the "
                             + ", ".join(e.name for e in ENGINES if e.api) + " engines")
    holes = _holes(args.fill_holes, args.keep_holes)
    if named:
        mesh, defaults = _named_mesh(V, holes, name)
    else:
        try:  # validated here: errors name no temporary file
            mesh, notes = oriented_mesh(vertices, faces, name="mesh" if name is None else name, holes=holes)
        except HoledMesh as exc:
            raise MeshError(f"{exc}{seams_hint(vertices, faces)}; {_in_api_words(HOLES_HINT)}") from None
        except MeshError as exc:
            raise MeshError(f"{exc}{repair_hint(exc)}{seams_hint(vertices, faces)}", faces=exc.faces,
                            vertices=exc.vertices, defect=exc.defect) from None
        for note in [*notes, *filter(None, [seams_note(vertices, faces)])]:
            warnings.warn(f"{mesh.name}: {note}", MeshNote, stacklevel=2)
        defaults = file_defaults(mesh)
    try:
        params = params_from_args(args, defaults, fixed_point=engine.fixed_point)
    except ParameterError as exc:  # the model's words are the command line's
        raise ParameterError(_in_api_words(str(exc))) from None
    args.mesh = mesh.name
    # the command's start for the mesh (a built-in's PCA, AUTO_START for arrays and files); an array is checked,
    # and untangled where it folds, as a layout file is
    run_notes: list[str] = []  # the command's notes on stderr (the start untangled, ...) are warnings here
    try:
        args.init = (default_init(str(V)) if named else AUTO_START) if init is None else \
            str(init) if isinstance(init, (str, Path)) else check_layout(init, mesh.n_vertices, ARRAY_WORDS)
        result = run_flatten(args, mesh, params, second_core=True, notes=run_notes)
    except FixedPointError as exc:  # the formats cannot hold the mesh: the presets that can, by keyword
        raise FixedPointError(_in_api_words(str(exc))) from None
    except (UserError, LayoutError, ParameterError) as exc:  # the command line's one line: options, or the start,
        raise ParameterError(_in_api_words(str(exc))) from None                 # refused
    except FormatSetNotBuildable as exc:  # engine="rtl"
        forget_half_built_components(exc)
        raise ParameterError(f"the RTL cannot be built with this format set: {exc}") from None
    notes = [*run_notes, divergence_note(params, result, api=True),
             *pattern_notes(params, mesh, result, api=True, formats=run_formats(args))]
    for note in filter(None, notes):
        warnings.warn(f"{mesh.name}: {note}", MeshNote, stacklevel=2)
    final = result.final
    ratio = area_ratio(result.positions, mesh.faces, mesh.face_areas)
    for array in (result.positions, ratio, mesh.vertices, mesh.faces, result.velocities, result.initial_positions):
        array.setflags(write=False)  # the values above are of these arrays, and the result is the Pattern's
    mesh_file = os.fspath(V) if named and not is_builtin(str(os.fspath(V))) else ""  # (a built-in's name: no file)
    read = input_files(argparse.Namespace(mesh=mesh_file,
                                          init=os.fspath(init) if isinstance(init, (str, Path)) else None,
                                          formats=options.get("formats") if isinstance(options.get("formats"), str)
                                          else None))
    read_files = tuple(Path(os.path.abspath(path)) for _, path in read if path is not None and os.path.isfile(path))
    return Pattern(result.positions, result.status, result.iterations, final.area_error, final.shape_error,
                   final.folded, ratio, mesh.name, mesh.vertices, mesh.faces, args.init, params, result, read_files)


def write_pattern(path: str | Path, pattern: Pattern, *, units: str = "mm", paper: str | None = None,
                  dxf_edges: bool = False, grain: str | Sequence[float] | None = None,
                  seam_allowance: float | str | None = None) -> None:
    """Write ``pattern`` to ``path``, the format named by its ending (as ``springflat flatten --out``).

    ``.dxf`` (cut line on layer ``CUT``; ``dxf_edges``: mesh edges on ``MESH``), ``.pdf`` / ``.svg`` (true
    scale on ``paper`` = ``a4`` (the default), ``a3``, ``letter`` or ``fit``, tiled with overlap marks), ``.obj`` (the
    3D mesh with the pattern as ``vt``), ``.flat.obj`` (the layout, z = 0), ``.flat.svg`` (the layout coloured
    by distortion).  ``grain`` (``x``, ``y``, ``z``, ``-z``, or ``"X,Y,Z"``): the pattern turned so that this 3D
    direction of the mesh, as laid on it, points up, with a grain line (as ``--grain``); by default the mesh as
    seen from its front (``docs/patterns.md``; ``Pattern.layout`` is the run's own frame).  ``seam_allowance`` (a length in ``units``, or a text with its unit: ``"10mm"``): the cut line
    runs this far outside the pattern's edge, which is drawn as the sew line (as ``--seam-allowance``; DXF, PDF
    and SVG only).  ``units`` (``mm``, ``cm``, ``m``, ``in``) is the mesh's length unit; see
    :mod:`sim.patterns`; a true-scale pattern (DXF, PDF, SVG) under 10 mm or over 5 m across gives a
    :class:`MeshNote` warning that ``units`` is likely wrong.  The file appears whole or not at all, and an
    existing regular file at ``path`` that may be written is replaced (a read-only one is refused), but for
    an ``.obj`` springflat did not write (a mesh, the pattern's own too: refused, as by the command) and a file
    the run read (``Pattern.read_files``: the mesh file, a start layout's, a format set's, even where springflat
    wrote them).

    Raises:
        OutputError: a path that cannot be written, or a ``diverged`` pattern (its last finite layout is no
            pattern: the command writes none either); ``dxf_edges`` without a ``.dxf`` path, ``paper``
            without a ``.pdf`` / ``.svg`` one, or ``seam_allowance`` without one of those three, which would
            ignore them.
        PatternError: a seam allowance that is not a length of 0 or more.
    """
    if not isinstance(path, (str, os.PathLike)):
        raise TypeError(f"write_pattern takes a file path (str or pathlib.Path), not {type(path).__name__}")
    if not isinstance(pattern, Pattern):
        raise TypeError(f"write_pattern takes the Pattern that flatten returns, not {type(pattern).__name__}")
    if not isinstance(dxf_edges, bool):
        raise TypeError(f"dxf_edges must be True or False, got {dxf_edges!r}")
    if isinstance(path, str) and not path.strip():
        raise OutputError(f"write_pattern: expected a file name, got {path!r}")
    if isinstance(path, str) and (problem := directory_name_problem(path)) is not None:
        raise OutputError(f"write_pattern: {problem}")
    if (problem := _nul_problem(path)) is not None:
        raise OutputError(f"write_pattern: {problem}")
    if (problem := ending_name_problem(Path(path), "write_pattern: the path")) is not None:
        raise OutputError(problem)
    if pattern.status == "diverged":
        raise OutputError(f"write_pattern: the run diverged after {pattern.iterations} iterations: its last finite "
                          "layout is no pattern")
    if dxf_edges and kind_or_none(path) != "dxf":
        raise OutputError(f"write_pattern: dxf_edges draws the mesh's edges into a DXF pattern, not '{path}'")
    if paper is not None and not on_sheets(path):
        raise OutputError(f"write_pattern: paper is the sheet of a PDF or SVG pattern, not '{path}'")
    if seam_allowance is not None and kind_or_none(path) not in TRUE_SCALE_KINDS:
        raise OutputError(f"write_pattern: seam_allowance draws the cut line of a DXF, PDF or SVG pattern, "
                          f"not '{path}'")
    try:  # a missing directory, a link to a mesh, ... named
        check_output_path(Path(path), "the path", typed=False)
        check_link_target(Path(path), "the path", pattern_ending)
        check_distinct([("the path", Path(path))], [("the run's input", file)
                                                    for file in pattern.read_files])
    except OutputError as exc:
        raise OutputError(f"write_pattern: {exc}") from None
    caption = run_caption(pattern.status, pattern.iterations, pattern.area_error, pattern.shape_error,
                          pattern.folded, pattern.boundary_crossings, pattern.turned_holes)
    try:
        drawing = PatternDrawing.of(pattern.mesh, pattern.layout, units, caption).as_seen()
        if grain is not None:
            drawing = drawing.with_grain(grain)
        if seam_allowance is not None:
            drawing = drawing.with_seam(seam_length(seam_allowance, units))
        write_pattern_file(Path(path), drawing, paper=DEFAULT_PAPER if paper is None else str(paper).lower(),
                           dxf_edges=dxf_edges)
    except PatternError as exc:  # the command's words for the same refusal ("check --units") in the API's
        raise PatternError(f"write_pattern: {_in_api_words(str(exc))}") from None
    if kind_or_none(path) in TRUE_SCALE_KINDS:
        for note in cut_file_notes(drawing, "units='{}'"):
            warnings.warn(f"{pattern.name}: {note}", MeshNote, stacklevel=2)


#: The pattern options of ``springflat flatten`` (``--units``, ``--paper``, ...): :func:`write_pattern`'s keywords.
_PATTERN_OPTIONS: Mapping[str, OptionSpec] = _record_options(add_pattern_options)

#: A flag in a message, and what follows it: one word, or a list of them (``a4, a3 or letter``), up to the next flag.
_FLAG = re.compile(r"(?P<drop>drop )?--(?P<no>no-)?(?P<name>[a-z][a-z0-9-]*)"
                   r"(?P<values> (?!--)[^\s,;:()]*[^\s,;:().](?:(?:, | or )(?!--)[^\s,;:()]*[^\s,;:().])*)?")

#: The words an option that takes any text (a method or a file, a preset or a file) takes as a value in a message.
_VALUE_WORDS: Mapping[str, Callable[[], Sequence[str]]] = {"formats": FormatSet.presets,
                                                         "init": lambda: (AUTO_START, *LAYOUT_METHODS)}


def _takes(spec: OptionSpec, word: str) -> bool:
    """Whether ``word`` is a value of the option (not the next word of the sentence): by its choices, its
    type, or (an option of any text: :data:`_VALUE_WORDS`) the words it names; a file name is never taken."""
    if spec.switch or spec.type in (file_path_argument, path_argument):
        return False
    if spec.choices is not None:
        return word in map(str, spec.choices)
    if spec.type is None:
        return spec.keyword in _VALUE_WORDS and word in _VALUE_WORDS[spec.keyword]()
    try:
        spec.type(word)
    except (argparse.ArgumentTypeError, TypeError, ValueError):
        return False
    return True


def _keyword_value(word: str) -> str:
    """A value as Python spells it: a number as it is, a word quoted."""
    try:
        float(word)
    except ValueError:
        return repr(word)
    return word


def _in_api_words(message: str) -> str:
    """A message of the command's, whose options are the command line's (``--units m``, ``--paper a4 or
    letter``, ``drop --damping``, ``use --no-guard``, ``drop --guard``), in the API's keywords (``units='m'``,
    ``paper='a4' or 'letter'``, ``drop damping``, ``use guard=False``, ``guard=False``): every option of
    :data:`OPTIONS` and of the pattern files, its values checked by the option's own type or choices."""
    def spelled(match: re.Match) -> str:
        keyword = match["name"].replace("-", "_")
        spec = OPTIONS.get(keyword) or _PATTERN_OPTIONS.get(keyword)
        if spec is None:
            return match[0]
        values = match["values"] or ""
        parts = re.split(r"(, | or )", values[1:]) if values else []
        taken = 0  # the words that are values: the first few, up to one that is the sentence's
        while taken < len(parts) and _takes(spec, parts[taken]):
            taken += 2
        rest = "".join(parts[taken - 1:]) if taken else values
        drop = match["drop"] or ""
        if spec.switch:  # what it is set to (dropping it: set the other way)
            on = not match["no"] if not drop else bool(match["no"])
            return f"{keyword}={on}{values}"
        if taken:
            return drop + f"{keyword}=" + "".join(part if k % 2 else _keyword_value(part)
                                                  for k, part in enumerate(parts[:taken - 1])) + rest
        return f"{drop}{keyword}{values}"

    return _FLAG.sub(spelled, message)


def _options_doc() -> str:
    lines = ["", "    Options (from ``springflat flatten``):", ""]
    for spec in OPTIONS.values():
        lines.append(f"    * ``{spec.keyword}`` (``{spec.flag}``): {_in_api_words(spec.help)}")
    return "\n".join(lines) + "\n"


flatten.__doc__ = (flatten.__doc__ or "") + _options_doc()
