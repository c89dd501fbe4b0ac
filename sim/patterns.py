"""Cutting patterns from a flattened mesh: DXF, true-scale PDF and SVG tiled onto paper, OBJ with ``vt``.

The writer is chosen by the file name's ending (:func:`pattern_kind`):

=============  ==========================================================================================
``.dxf``       the boundary as closed ``LWPOLYLINE`` entities on layer ``CUT``, the outer edge and each kept hole's
               (with a seam allowance the cut line there, the boundary on layer ``SEW``); with ``dxf_edges`` every mesh
               edge as a ``LINE`` on layer ``MESH``; with a grain (``--grain``) its line on layer ``GRAIN``;
               coordinates in the mesh's units, 1:1, ``$INSUNITS`` and ``$MEASUREMENT`` set from ``units``
               (ezdxf).
``.pdf``       true scale (1 mm of pattern = 1 mm of paper for ``units="mm"``), on ``paper`` sheets
               (A4, A3, Letter, or ``fit``: one page around the pattern), tiled with overlap marks when the
               pattern is larger than one sheet (a sheet that would hold nothing of it is left out);
               every sheet carries the mesh's name, the units, the run, its label when tiled and a scale
               bar to check the print, and the piece its name (reportlab).
``.svg``       the same sheets as the PDF in one SVG document, user unit = 1 mm; tiled sheets lie side
               by side in their grid, each declared as an Inkscape page.
``.obj``       the 3D mesh (``v``, full precision) with the pattern as texture coordinates ``vt`` (scaled
               into [0, 1], the factor in a comment) and ``f v/vt`` corners.
``.flat.obj``  the flat layout as OBJ with z = 0 and the same faces (:func:`sim.outputs.write_layout`).
``.flat.svg``  the flat layout in mesh units, faces coloured by area distortion (:func:`sim.outputs.write_layout`).
=============  ==========================================================================================

Every file is written through :func:`sim.outputs.atomic_write` (no partial file on an error) and is
byte-for-byte reproducible: no dates, GUIDs or random IDs (ezdxf's fixed metadata, reportlab's
``invariant`` mode).  Units are stated in every file (DXF header, PDF/SVG title block, OBJ comment).

Sheet geometry (page coordinates in millimetres, origin at the lower left, y up): a margin of
:data:`MARGIN_MM` on every side, a title block of :data:`TITLE_MM` at the bottom, and the pattern's
window above it.  Adjacent windows share a strip of :data:`OVERLAP_MM`: a grey chain line on each sheet
(:data:`GUIDE_DASH_MM`, unlike the sew line's dashes) shows where its neighbour's window begins, with
crosses where that line meets the window's frame, so that sheets are trimmed along one frame edge and laid
onto the neighbour's chain line.
"""

from __future__ import annotations

import argparse
import math
import os
import re
import stat
from dataclasses import dataclass, replace
from functools import cached_property
from pathlib import Path
from typing import Callable, Sequence
from xml.sax.saxutils import escape

import numpy as np

from golden_model.mesh import Mesh, folded_faces, loop_length, loop_signed_area, overlap_counts, signed_areas_2d

from .mesh_io import save_obj
from .mesh_io.polygons import plural
from .outputs import OutputError, atomic_write, output_target, write_layout
from .run_options import OneOutput, file_path_argument

#: Length units a mesh may be in, and millimetres per unit.
UNIT_MM = {"mm": 1.0, "cm": 10.0, "m": 1000.0, "in": 25.4}
UNITS = tuple(UNIT_MM)
UNIT_NAMES = {"mm": "millimetres", "cm": "centimetres", "m": "metres", "in": "inches"}
#: DXF ``$INSUNITS`` codes of :data:`UNITS` (AutoCAD: 1 inches, 4 millimetres, 5 centimetres, 6 metres).
DXF_INSUNITS = {"mm": 4, "cm": 5, "m": 6, "in": 1}
#: The sheets ``--paper`` names: (the name a sheet's label prints, portrait width and height in mm); ``fit``
#: is one page around the pattern (:data:`FIT_PAD_MM`, the margin and the title block).
PAPER_SHEETS = {"a4": ("A4", 210.0, 297.0), "a3": ("A3", 297.0, 420.0), "letter": ("Letter", 215.9, 279.4)}
PAPER_MM = {paper: (width, height) for paper, (_, width, height) in PAPER_SHEETS.items()}
PAPERS = (*PAPER_MM, "fit")
#: The sheet when none is named (``--paper``, ``write_pattern``'s ``paper``).
DEFAULT_PAPER = "a4"
#: The pattern kinds drawn on sheets of ``paper``.
SHEET_KINDS = ("pdf", "svg")
#: The pattern kinds at 1:1 in ``units`` (a print, or a cut line); the others are texture or layout files.
TRUE_SCALE_KINDS = ("dxf", *SHEET_KINDS)
#: What ``--out`` accepts (:func:`pattern_kind` tells the kind of each).
PATTERN_SUFFIXES = (".dxf", ".pdf", ".svg", ".obj")

MARGIN_MM = 10.0          # unprinted border on every side
TITLE_MM = 22.0           # the title block under the window
OVERLAP_MM = 10.0         # strip shared by adjacent windows
FIT_PAD_MM = 5.0          # room around the pattern in a ``fit`` window
FIT_MIN_WIDTH_MM = 160.0  # a ``fit`` page is at least this wide (room for the title block)
SVG_GAP_MM = 10.0         # space between tiled sheets in an SVG
CUT_WIDTH_MM = 0.3        # the cut line
SEW_WIDTH_MM = 0.2        # the sew line, inside the cut line when there is a seam allowance ...
SEW_DASH_MM = (3.0, 1.5)  # ... dashed: on and off
#: The overlap guides' chain line (on, off, on, off; mm): not to be taken for the sew line's dashes.
GUIDE_DASH_MM = (6.0, 1.5, 0.5, 1.5)
#: The overlap guides' grey (0 black, 1 white).
GUIDE_GREY = 0.45
SEAM_ARC_SEGMENTS = 32    # chords a quarter circle has where the cut line turns round a corner of the sew line
SEAM_MARGIN = 1e-3        # the cut line is at least the allowance, at most this share more, from the sew line
EDGE_WIDTH_MM = 0.06      # mesh edges, drawn only when ...
EDGE_MIN_MM = 2.0         # ... the median edge is at least this long on paper
GRAIN_WIDTH_MM = 0.2      # the grain line and its arrowheads (--grain) ...
GRAIN_GREY = 0.35         # ... in this grey (0 black, 1 white)
PIECE_LABEL_MAX_MM = 6.0  # the piece's name on the piece itself: at most this tall (cap height) ...
PIECE_LABEL_MIN_MM = 1.5  # ... and left out where it would be smaller than this to fit
GRAIN_CLEARANCE_MM = 1.0  # ... and this far from the grain line
DESCENDER_EM = 0.21       # Helvetica's descender, in font sizes (below the baseline: g, p, y)
SCALE_BAR_MAX_MM = 80.0   # the scale bar is the longest 1, 2 or 5 x 10^k units not longer than this
FONT_MM = 3.2             # text height of the title block
CAP_HEIGHT_EM = 0.72      # Helvetica's cap height, in font sizes (a label's size is its cap height)
MIN_TEXT_SCALE = 0.6      # a title-block line too long for its room is set down to this fraction, then cut
TEXT_GAP_MM = 5.0         # between the title block's left column and the scale bar
MAX_SHEETS = 400          # more sheets than this is a wrong --units, not a pattern to print
SMALL_PATTERN_MM = 10.0   # a pattern smaller than this at 1:1 gets a note about --units
LARGE_PATTERN_MM = 5000.0  # ... and one larger than this (a DXF has no sheet limit to refuse it)
PT_PER_MM = 72.0 / 25.4
MAX_PAGE_MM = 14400 / PT_PER_MM  # a PDF page's largest side, 14,400 pt (PDF 1.7, annex C): 5.08 m


class PatternError(OutputError):
    """A pattern that cannot be written as asked (a bad unit, paper or file ending); one line."""


def pattern_kind(path: Path) -> str:
    """``dxf``, ``pdf``, ``svg``, ``obj``, ``flat.obj`` or ``flat.svg`` from the file name's ending."""
    name = Path(path).name.lower()
    for kind in ("flat.obj", "flat.svg", "dxf", "pdf", "svg", "obj"):
        if name.endswith("." + kind):
            return kind
    raise PatternError(f"'{path}' must end in {', '.join(PATTERN_SUFFIXES)} (or .flat.obj, .flat.svg)")


def kind_or_none(path: Path | str) -> str | None:
    """:func:`pattern_kind` of ``path`` (or of a batch's ending), ``None`` for a name no pattern has."""
    try:
        return pattern_kind(Path(path))
    except PatternError:
        return None


def pattern_ending(path: Path | str) -> str | None:
    """The ending that names ``path``'s pattern kind (``.pdf``, ``.flat.obj``), ``None`` for a name no pattern
    has: what a symbolic link's target must share with the link (:func:`sim.outputs.check_output_path`)."""
    kind = kind_or_none(path)
    return None if kind is None else "." + kind


def on_sheets(path: Path | str) -> bool:
    """Whether ``path`` (or a batch's ending) names a pattern drawn on paper sheets, ``--paper``'s:
    ``.pdf`` or ``.svg``, not ``.flat.svg``."""
    return kind_or_none(path) in SHEET_KINDS


def check_units(units: str) -> float:
    """Millimetres per unit of ``units`` (one of :data:`UNITS`)."""
    if units not in UNIT_MM:
        raise PatternError(f"units must be one of {', '.join(UNITS)}, got {units!r}")
    return UNIT_MM[units]


def add_pattern_options(parser: argparse.ArgumentParser) -> None:
    """The ``flatten`` options of the pattern outputs (``--units``, ``--paper``, ``--dxf-edges``, ``--distortion``)."""
    parser.add_argument("--units", choices=UNITS, default="mm",
                        help="the mesh's length unit, stated in every pattern file and used for true-scale "
                             "PDF/SVG and DXF $INSUNITS (default mm)")
    parser.add_argument("--paper", type=str.lower, choices=PAPERS, default=None,  # None: not given (DEFAULT_PAPER)
                        help=f"PDF/SVG sheet: {_either(list(PAPER_MM))} (tiled with overlap marks when the pattern is "
                             "larger; any case), "
                             f"or fit: one page around the pattern, for a roll plotter (default {DEFAULT_PAPER}); "
                             "a cutter takes the .dxf, whose layer CUT holds the cut line alone (SEW: the sew line of "
                             "--seam-allowance, MESH: --dxf-edges)")
    parser.add_argument("--grain", type=grain_argument, default=None, metavar="x|y|z|X,Y,Z",
                        help="turn the pattern files so that this 3D direction of the mesh (-z: the other way), as "
                             "laid on the pattern, points up the page, and draw it as a grain line (default: the "
                             "mesh as seen from its front, turned to fit the sheets)")
    parser.add_argument("--seam-allowance", type=seam_allowance_argument, default=None, metavar="LENGTH",
                        help="add a seam allowance: the cut line runs this far outside the pattern's edge, which is "
                             "drawn as the sew line (dashed; DXF layer SEW); a length in --units, or with its "
                             "unit: 10mm, 1.5cm, 0.375in (default: none, the pattern's edge is the cut line)")
    parser.add_argument("--dxf-edges", action="store_true",
                        help="also write every mesh edge to the DXF, on layer MESH (the cut line is on CUT)")
    parser.add_argument("--distortion", type=file_path_argument, action=OneOutput, default=None, metavar="FILE.csv",
                        help="per-triangle area ratio and per-edge strain as CSV")


# --------------------------------------------------------------------------- what is drawn


@dataclass(frozen=True)
class PatternDrawing:
    """A flattened mesh as the writers need it.

    Attributes:
        name: the mesh's name, printed on every sheet.
        vertices: ``(V, 3)`` the 3D mesh, in ``units``.
        faces: ``(F, 3)`` vertex indices.
        layout: ``(V, 2)`` the pattern, in ``units``.
        boundary: ``(B,)`` the outer edge's vertex indices in order (:attr:`Mesh.boundary_loop`).
        edges: ``(E, 2)`` the unique edges (:attr:`Mesh.edges`).
        units: one of :data:`UNITS`.
        caption: one line about the run (status, errors), printed under the name.
        grain: the 3D direction the pattern was turned to carry up the page (:meth:`with_grain`), as the
            user named it (``z``, ``1,0,0``), or ``""``: no grain line (the frame is the layout's, or the mesh's
            view after :meth:`as_seen`).
        grain_agreement: how well the grain direction's pieces on the pattern agree (:func:`grain_axis`: 1 all
            along one line, 0 every way).
        seam: the seam allowance in ``units`` (:meth:`with_seam`): the cut line runs this far outside the
            boundary, which becomes the sew line; 0: the boundary is the cut line.
        holes: each kept hole's edge, vertex indices in order (:attr:`Mesh.boundary_loops` after the first):
            cut-outs, which the cut line and the sew line go round too.
        turn: the angle (radians, anticlockwise) ``layout`` is turned by from the layout it was made of
            (:meth:`as_seen`, :meth:`with_grain`), for a figure of the run to show it the same way.
    """

    name: str
    vertices: np.ndarray
    faces: np.ndarray
    layout: np.ndarray
    boundary: np.ndarray
    edges: np.ndarray
    units: str = "mm"
    caption: str = ""
    grain: str = ""
    seam: float = 0.0
    holes: tuple[np.ndarray, ...] = ()
    grain_agreement: float = 1.0
    turn: float = 0.0

    @classmethod
    def of(cls, mesh: Mesh, layout: np.ndarray, units: str = "mm", caption: str = "") -> "PatternDrawing":
        layout = np.asarray(layout, dtype=np.float64)
        if layout.shape != (mesh.n_vertices, 2):
            raise PatternError(f"the layout must have shape ({mesh.n_vertices}, 2), got {layout.shape}")
        if not np.isfinite(layout).all():
            raise PatternError("the layout has a non-finite coordinate")
        check_units(units)
        return cls(mesh.name, mesh.vertices, mesh.faces, layout, mesh.boundary_loop, mesh.edges, units, caption,
                   holes=tuple(mesh.boundary_loops[1:]))

    @property
    def boundary_points(self) -> np.ndarray:
        """``(B, 2)`` the pattern's outer edge, in ``units`` (closed: the last joins the first): the cut line, or
        the sew line where there is a seam allowance."""
        return self.edge_loops[0]

    def boundary_length(self) -> float:
        """Length of the pattern's closed outer edge, in ``units``."""
        return loop_length(self.boundary_points)

    @cached_property
    def edge_loops(self) -> list[np.ndarray]:
        """The pattern's edge as closed loops of ``(B, 2)`` points in ``units``: its outer edge, then each kept
        hole's. The outer edge is the loop that encloses the most area in the layout (whichever loop of the mesh
        it is: a ring's inner edge can end up outside)."""
        loops = [self.layout[loop] for loop in (self.boundary, *self.holes)]
        outer = max(range(len(loops)), key=lambda k: abs(loop_signed_area(loops[k])))
        return [loops[outer], *loops[:outer], *loops[outer + 1:]]

    @cached_property
    def overlapping(self) -> bool:
        """:func:`overlaps`, kept."""
        return overlaps(self)

    @cached_property
    def covered(self):
        """The area the pattern covers (:func:`material`), kept: the seam allowance and the grain line ask."""
        return material(self)

    @cached_property
    def hole_cuts(self) -> list[tuple[bool, bool]]:
        """``(covered, cut_out)`` of each kept hole, kept (the covered- and closed-hole notes ask): more than half
        the area inside its loop is material (a flap of an overlapping pattern over it), and a loop of the cut line
        beyond the outer one lies inside it (the cut line goes round some of it)."""
        import shapely

        openings = [shapely.Polygon(loop).representative_point() for loop in self.cut_loops[1:]]
        cuts = []
        for loop in self.edge_loops[1:]:
            inside = shapely.make_valid(shapely.Polygon(loop))  # (a hole the pattern wraps over may cross itself)
            covered = self.overlapping and inside.area > 0 and inside.intersection(self.covered).area > inside.area / 2
            cuts.append((bool(covered), any(inside.contains(point) for point in openings)))
        return cuts

    @cached_property
    def cut_loops(self) -> list[np.ndarray]:
        """The cut line's closed loops, in ``units``: the edge's (:attr:`edge_loops`), or the seam allowance's
        outline (:func:`seam_outlines`: the outer loop first, then any hole the allowance leaves inside it)."""
        return seam_outlines(self, self.seam) if self.seam > 0 else self.edge_loops

    @property
    def cut_points(self) -> np.ndarray:
        """``(K, 2)`` the cut line's outer loop's corners, in ``units`` (closed)."""
        return self.cut_loops[0]

    @property
    def drawn_points(self) -> np.ndarray:
        """Every point that sets the drawing's extent: the layout and the cut line, in ``units``."""
        return np.vstack([self.layout, self.cut_points]) if self.seam > 0 else self.layout

    def with_seam(self, allowance: float) -> "PatternDrawing":
        """The drawing with a seam allowance of ``allowance`` ``units`` (0: none), checked against the longer of
        its edge's 2D and 3D lengths (:func:`check_seam_fits`; the command checks the 3D one before the run)."""
        if not (math.isfinite(allowance) and allowance >= 0):
            raise PatternError(f"a seam allowance is {LENGTH_AT_LEAST_0}, got {allowance!r}")
        edge = max(self.boundary_length(), loop_length(self.vertices[self.boundary]))
        check_seam_fits(allowance, edge, self.units)
        return replace(self, seam=float(allowance))

    def as_seen(self) -> "PatternDrawing":
        """The drawing turned as the mesh is seen from its front (:func:`view_turn`): a piece modelled flat in
        x, y comes back in x, y, and a curved one as it looks from along its mean normal."""
        angle = view_turn(self.vertices, self.faces, self.layout)
        return replace(self, layout=_turned(self.layout, angle, _centre(self.layout)), turn=self.turn + angle)

    def with_grain(self, grain: str | Sequence[float]) -> "PatternDrawing":
        """The drawing turned so that the 3D direction ``grain`` (:func:`grain_direction`), as the triangles
        carry it onto the pattern, points up (+y), with a grain line on every pattern file."""
        angle, agreement = grain_axis(self.vertices, self.faces, self.layout, grain_direction(grain))
        return replace(self, layout=_turned(self.layout, math.pi / 2 - angle, _centre(self.layout)),
                       grain=grain_text(grain), grain_agreement=agreement, turn=self.turn + math.pi / 2 - angle)

    def grain_line(self) -> np.ndarray:
        """``(2, 2)`` the grain line's ends (bottom, top) in ``units``: vertical, through the vertex nearest the
        pattern's area centroid, :data:`GRAIN_LINE_FRACTION` of its height long; where that line leaves the
        piece (a hole, a C-shaped piece's gap), on the vertical through the piece that runs longest in it
        (:func:`grain_on_material`)."""
        return self._grain_ends.copy()

    @cached_property
    def _grain_ends(self) -> np.ndarray:
        """:meth:`grain_line`'s, kept: each sheet writer and the piece label ask."""
        q = self.layout[self.faces]
        a, b = q[:, 1] - q[:, 0], q[:, 2] - q[:, 0]
        areas = np.abs(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]) / 2
        centroid = (areas[:, None] * q.mean(axis=1)).sum(axis=0) / areas.sum()
        x, y = self.layout[np.argmin(np.linalg.norm(self.layout - centroid, axis=1))]
        half = GRAIN_LINE_FRACTION * float(np.ptp(self.layout[:, 1])) / 2
        line = np.array([[x, y - half], [x, y + half]])
        return grain_on_material(line, self.covered, float(centroid[0]))


def seam_allowance_argument(text: str) -> str:
    """``--seam-allowance``: a length, bare (in ``--units``) or with one of :data:`UNITS` (``10mm``), checked
    here and turned into ``--units`` by :func:`seam_length` once those are known."""
    try:
        seam_length(text, "mm")
    except NotALength as exc:
        raise argparse.ArgumentTypeError(f"expected {exc.wanted}, got {text!r}") from None
    return text


#: What a seam allowance must be, as its refusals say.
LENGTH_EXAMPLE = "a length such as 10, 10mm or 0.375in"
LENGTH_AT_LEAST_0 = "a length of 0 or more"


class NotALength(PatternError):
    """A seam allowance that is no length: ``wanted`` says what it must be."""

    def __init__(self, wanted: str, value: object):
        super().__init__(f"a seam allowance is {wanted}, got {value!r}")
        self.wanted = wanted


#: A seam allowance's text: a decimal number (ASCII digits), then one of :data:`UNITS` as written (SI symbols are
#: case-sensitive: ``M`` would be mega), or none (the pattern's ``--units``).
_LENGTH = re.compile(r"\s*(?P<number>[+-]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][+-]?[0-9]+)?)\s*"
                     rf"(?P<unit>{'|'.join(sorted(UNIT_MM, key=len, reverse=True))})?\s*")


def seam_length(value: str | float, units: str) -> float:
    """A seam allowance in ``units``: a number is in ``units`` already, a text may end in a unit (``10mm``,
    ``1.5 cm``; :data:`_LENGTH`). Anything else raises :class:`NotALength`."""
    scale = check_units(units)
    unit = units
    if isinstance(value, str):
        match = _LENGTH.fullmatch(value)
        if match is None:
            raise NotALength(LENGTH_EXAMPLE, value)
        number, unit = float(match["number"]), match["unit"] or units
    elif isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise NotALength(LENGTH_EXAMPLE, value)
    else:
        try:
            number = float(value)
        except OverflowError:  # an int past float's range
            number = math.inf
    if not math.isfinite(number):  # (a text such as 1e400 too)
        raise NotALength(LENGTH_EXAMPLE, value)
    if number < 0:
        raise NotALength(LENGTH_AT_LEAST_0, value)
    number += 0.0  # -0 is 0
    length = number if unit == units else number * UNIT_MM[unit] / scale
    if not math.isfinite(length):  # (1e306m in mm)
        raise NotALength(LENGTH_EXAMPLE, value)
    return length


def check_seam_fits(allowance: float, edge_length: float, units: str) -> None:
    """Refuse a seam allowance (in ``units``) longer than half the pattern's edge (``edge_length`` ``units``
    round; a pattern is never wider than that): a wrong unit, most likely (``10`` meant as mm with ``--units
    m``), which would make the print a refusal for its size and the cut line a blob."""
    if allowance > edge_length / 2:
        raise PatternError(f"a seam allowance of {length_text(allowance, units)} is more than half the length of the "
                           f"pattern's edge, {length_text(edge_length, units)}: check its length and unit (10mm, "
                           "0.375in)")


def length_text(length: float, units: str) -> str:
    """A length in ``units`` as the sheets and messages print it, in mm too for a ruler: ``0.01 m (10 mm)``,
    ``0.375 in (9.525 mm)``, ``10 mm``."""
    return f"{length:.6g} {units}" + (f" ({length * UNIT_MM[units]:.6g} mm)" if units != "mm" else "")


def cut_file_notes(drawing: PatternDrawing, units_option: str = "--units {}") -> list[str]:
    """The notes on a pattern written at 1:1 (a print or a cut): :func:`scale_note` (``units_option`` as there),
    :func:`covered_holes_note`, :func:`grain_note` and :func:`closed_holes_note`, those that have something to
    say."""
    notes = (scale_note(drawing, units_option), covered_holes_note(drawing), grain_note(drawing),
             closed_holes_note(drawing))
    return [note for note in notes if note is not None]


def closed_holes_note(drawing: PatternDrawing) -> str | None:
    """Kept holes that the seam allowance closes on the cut line (a hole narrower than twice the allowance, or
    what an overlapping pattern leaves of it): the cut line goes round no part of them, so they are cut after
    sewing, along their sew line; ``None`` if none. A hole a flap covers is :func:`covered_holes_note`'s."""
    if drawing.seam <= 0 or not drawing.holes:
        return None
    closed = sum(not cut_out and not covered for covered, cut_out in drawing.hole_cuts)
    if not closed:
        return None
    which, are, them = _holes_words(closed, len(drawing.holes))
    return (f"{which} {are} narrower than twice the seam allowance ({length_text(drawing.seam, drawing.units)}): "
            f"the cut line does not go round {them}; cut {them} out along the sew line after sewing")


def covered_holes_note(drawing: PatternDrawing) -> str | None:
    """Kept holes that a flap of the pattern covers where it overlaps itself (:func:`overlaps`): more than half
    the area inside the hole's loop is material. With a seam allowance, those the cut line has no cut-out for
    (its outline goes round the material); without one, each of them (its loop on the cut line runs over the
    material); ``None`` if none."""
    if not drawing.holes or not drawing.overlapping:
        return None
    covered = sum(covered and not (drawing.seam > 0 and cut_out) for covered, cut_out in drawing.hole_cuts)
    if not covered:
        return None
    which, are, them = _holes_words(covered, len(drawing.holes))
    return (f"{which} {are} covered by the pattern where it lies on itself: the cut line "
            + (f"has no cut-out for {them}" if drawing.seam > 0 else f"round {them} runs over the material"))


def _holes_words(some: int, count: int) -> tuple[str, str, str]:
    """``(which, are, them)`` for ``some`` of a pattern's ``count`` kept holes: ``("1 of the 3 kept holes",
    "is", "it")``, ``("both kept holes", "are", "them")``, ..."""
    which = (f"{some} of the {count} kept holes" if some < count else "the kept hole" if some == 1
             else "both kept holes" if some == 2 else f"all {some} kept holes")
    return (which, "are", "them") if some > 1 else (which, "is", "it")


def seam_outlines(drawing: PatternDrawing, allowance: float) -> list[np.ndarray]:
    """The closed loops of the cut line ``allowance`` outside the pattern's material (:func:`material`), outer
    loop first: the outline of the points within that distance of it (shapely's buffer, round joins), so every
    point of the sew line has the full allowance, and the zigzag of a scanned boundary's short edges is not
    carried out to the cut line (mitred joins would make each of its bends a spike). The buffer is
    :data:`SEAM_MARGIN` wider than asked: its rounded corners are chords, and GEOS simplifies the outline by a
    small share of the distance first, each of which brings the line a little closer (up to 0.05 % on a scan).
    A hole the allowance leaves (a C-shaped piece whose slit the allowances close, a pattern that overlaps
    itself round an empty middle) is a loop of the cut line too: its middle is no material. The outer loop
    runs counter-clockwise and the holes clockwise, as the sew line does on a pattern seen from the mesh's
    front (a cutter's offset side follows a loop's direction; GEOS gives them the other way round)."""
    from shapely.geometry.polygon import orient

    grown = drawing.covered.buffer(allowance * (1 + SEAM_MARGIN), quad_segs=SEAM_ARC_SEGMENTS)
    parts = getattr(grown, "geoms", [grown])
    largest = orient(max(parts, key=lambda part: part.area), sign=1.0)
    return [np.asarray(ring.coords, dtype=np.float64)[:-1] for ring in (largest.exterior, *largest.interiors)]


def overlaps(drawing: PatternDrawing) -> bool:
    """Whether parts of the pattern lie on each other: a triangle folded, sides of its boundary that meet
    (:func:`~golden_model.mesh.boundary_crossings`) or a hole it wraps over
    (:func:`~golden_model.mesh.turned_holes`)."""
    if folded_faces(drawing.layout, drawing.faces).any():
        return True
    crossings, turned = overlap_counts(drawing.layout, drawing.faces, [drawing.boundary, *drawing.holes])
    return bool(crossings or turned)


def edge_polygon(loops: list[np.ndarray]):
    """The shapely polygon of a pattern's edge loops that do not overlap (:func:`overlaps`), the outer edge
    first (:attr:`PatternDrawing.edge_loops`), the others its holes."""
    import shapely

    return shapely.Polygon(loops[0], loops[1:])


def material(drawing: PatternDrawing):
    """The area the pattern covers, a shapely geometry in ``units``: the polygon of its edge (:func:`edge_polygon`),
    or, where parts of the pattern lie on each other (:func:`overlaps`), the union of its triangles (a folded
    flap can lie outside the boundary's polygon). :attr:`PatternDrawing.covered` keeps it."""
    import shapely

    if not drawing.overlapping:
        return edge_polygon(drawing.edge_loops)
    kept = signed_areas_2d(drawing.layout, drawing.faces) != 0  # (a triangle of no area covers nothing)
    return shapely.union_all(shapely.polygons(drawing.layout[drawing.faces[kept]]))


#: Verticals :func:`grain_on_material` tries across the piece.
GRAIN_CANDIDATES = 64
#: The share of the longest vertical stretch across the piece that a moved grain line takes at most.
GRAIN_STRETCH_SHARE = 0.9


def grain_on_material(line: np.ndarray, area, centre_x: float) -> np.ndarray:
    """``line`` (vertical, ``(2, 2)``) where it lies on ``area`` (the piece's material, shapely, allowing for
    rounding); else the longest stretch of any of :data:`GRAIN_CANDIDATES` verticals across ``area`` (the one
    nearest ``centre_x`` among the longest), with a line as long as ``line``, or :data:`GRAIN_STRETCH_SHARE`
    of that stretch where that is shorter, about its middle: a grain line that crossed a hole or a gap would
    be laid on nothing."""
    import shapely

    size = max(float(np.ptp(np.asarray(area.bounds).reshape(2, 2), axis=0).max()), 1e-300)
    if area.buffer(1e-9 * size).covers(shapely.LineString(line)):  # (its ends may lie on the edge)
        return line
    low_x, low_y, high_x, high_y = area.bounds
    best = None
    for x in np.linspace(low_x, high_x, GRAIN_CANDIDATES + 2)[1:-1]:
        across = area.intersection(shapely.LineString([(x, low_y - 1), (x, high_y + 1)]))
        for piece in getattr(across, "geoms", [across]):
            if piece.geom_type != "LineString" or piece.is_empty:
                continue
            key = (round(piece.length / size, 6), -abs(x - centre_x))
            if best is None or key > best[0]:
                best = (key, x, piece.bounds[1], piece.bounds[3])
    if best is None:  # (an area no vertical crosses: the line as it was)
        return line
    _, x, bottom, top = best
    half = min(float(line[1, 1] - line[0, 1]), GRAIN_STRETCH_SHARE * (top - bottom)) / 2
    middle = (bottom + top) / 2
    return np.array([[x, middle - half], [x, middle + half]])


#: A grain line's length, as a fraction of the pattern's height, and its arrowheads', of its length.
GRAIN_LINE_FRACTION = 0.5
GRAIN_HEAD_FRACTION = 0.06


def grain_argument(text: str) -> str:
    """``--grain``'s value, checked (:func:`grain_direction`) and kept as typed."""
    try:
        grain_direction(text)
    except PatternError as exc:
        raise argparse.ArgumentTypeError(str(exc).removeprefix(f"--grain {text!r}: ")) from None
    return text


def check_grain(mesh: Mesh, text: str) -> None:
    """Refuse, before a run, a grain direction normal to the whole surface (:func:`_along_surface`)."""
    _along_surface(mesh.vertices[mesh.faces], grain_direction(text))


def grain_arrow(line: np.ndarray) -> list[np.ndarray]:
    """A grain line's strokes: the line (bottom, top) and an arrowhead at each end (three points each)."""
    (x, y0), (_, y1) = line
    head = GRAIN_HEAD_FRACTION * (y1 - y0)
    return [line, np.array([[x - head / 2, y1 - head], [x, y1], [x + head / 2, y1 - head]]),
            np.array([[x - head / 2, y0 + head], [x, y0], [x + head / 2, y0 + head]])]
#: ``--grain``'s named directions.
GRAIN_AXES = {"x": (1.0, 0.0, 0.0), "y": (0.0, 1.0, 0.0), "z": (0.0, 0.0, 1.0)}


def grain_direction(grain: str | Sequence[float]) -> np.ndarray:
    """``--grain``'s 3D direction: ``x``, ``y``, ``z`` (``-z``: the other way) or three numbers ``X,Y,Z`` in the
    mesh's frame (the API also takes a sequence of three); a unit vector, or :class:`PatternError`."""
    try:
        text = grain_text(grain)
    except (TypeError, ValueError):  # not a string, nor a sequence of numbers
        text = repr(grain)
    word = text.strip().lower()
    sign, axis = (-1.0, word[1:]) if word.startswith("-") and word[1:] in GRAIN_AXES else (1.0, word)
    try:
        vector = sign * np.array(GRAIN_AXES[axis]) if axis in GRAIN_AXES else np.array(
            [float(part) for part in text.split(",")])
    except ValueError:
        vector = np.empty(0)
    if vector.shape != (3,) or not np.isfinite(vector).all() or not np.abs(vector).max() > 0:
        raise PatternError(f"--grain {text!r}: expected x, y or z (-z: the other way) or a 3D direction X,Y,Z "
                           "that is not zero")
    vector = vector / np.abs(vector).max()  # (1e308 or 1e-320 components: the norm neither overflows nor vanishes)
    return vector / np.linalg.norm(vector)


def grain_text(grain: str | Sequence[float]) -> str:
    """A grain as the files name it: as typed, or ``X,Y,Z`` for the API's sequence (``TypeError`` or
    ``ValueError`` for anything else)."""
    return grain if isinstance(grain, str) else ",".join(f"{float(v):g}" for v in grain)


def _along_surface(triangles: np.ndarray, direction: np.ndarray) -> None:
    """:class:`PatternError` where ``direction`` is normal to the surface of ``triangles`` (``(F, 3, 3)``): its
    part in their planes, weighted by their areas, is below a millionth of it."""
    normals = np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0])  # 2 × area long
    double_area = np.linalg.norm(normals, axis=1)
    in_plane = np.linalg.norm(np.cross(normals, direction), axis=1).sum()  # Σ 2·area·|direction's plane part|
    if not in_plane > 1e-6 * double_area.sum():
        raise PatternError("--grain: the direction is normal to the surface (it lies in none of its triangles): it "
                           "has no direction on the pattern; name one along the surface")


#: A grain whose pieces on the pattern agree less than this (:func:`grain_axis`) gets a note (:func:`grain_note`):
#: their doubled angles' weighted mean is shorter than half their weight, so they spread by about ±45° or more.
GRAIN_AGREEMENT = 0.5


def grain_axis(vertices: np.ndarray, faces: np.ndarray, layout: np.ndarray,
               direction: np.ndarray) -> tuple[float, float]:
    """``(angle, agreement)``: the angle (radians, anticlockwise from +x) at which ``direction`` (a 3D unit
    vector) lies on the pattern, and how well its pieces agree on it (the length of their doubled angles'
    weighted mean over their total weight: 1 all along one line, 0 every way).

    Each triangle's affine map carries the direction's part in its plane onto the layout. A grain is an axis:
    those pieces are averaged as axes (their doubled angles, each weighted by its length and its triangle's 3D
    area), so that pieces pointing opposite ways along one line (across a half-pipe, say) reinforce rather than
    cancel; the axis is then pointed the way most of them point. :class:`PatternError` where the direction is
    normal to the surface (:func:`_along_surface`), or its pieces point every way."""
    p, q = vertices[faces], layout[faces]
    e1, e2 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
    u1, u2 = q[:, 1] - q[:, 0], q[:, 2] - q[:, 0]
    g11, g12, g22 = (e1 * e1).sum(axis=1), (e1 * e2).sum(axis=1), (e2 * e2).sum(axis=1)
    r1, r2 = e1 @ direction, e2 @ direction
    gram = g11 * g22 - g12 * g12  # (2 × the 3D area)²: the direction's plane part is a·e1 + b·e2
    area = np.sqrt(gram) / 2
    _along_surface(p, direction)
    a, b = (g22 * r1 - g12 * r2) / gram, (g11 * r2 - g12 * r1) / gram
    pieces = a[:, None] * u1 + b[:, None] * u2
    length = np.linalg.norm(pieces, axis=1)
    weight = np.divide(area, length, out=np.zeros_like(area), where=length > 0)  # area × length × (unit doubled)
    doubled = np.column_stack([pieces[:, 0] ** 2 - pieces[:, 1] ** 2, 2 * pieces[:, 0] * pieces[:, 1]])
    axis = (weight[:, None] * doubled).sum(axis=0)
    weight_sum = float((area * length).sum())
    agreement = float(np.linalg.norm(axis)) / weight_sum if weight_sum > 0 else 0.0  # (a layout collapsed to a point)
    if not agreement > 1e-3:
        raise PatternError("--grain: the direction's pieces on the pattern point every way (no one line carries "
                           "it): name another")
    angle = float(np.arctan2(axis[1], axis[0])) / 2
    along = (area[:, None] * pieces).sum(axis=0) @ np.array([math.cos(angle), math.sin(angle)])
    return (angle if along >= 0 else angle + math.pi), agreement


def view_turn(vertices: np.ndarray, faces: np.ndarray, layout: np.ndarray) -> float:
    """The rotation (radians, anticlockwise) that best lays ``layout`` onto the mesh as seen from its front: the
    mesh projected along its vector area's normal ``n`` (the side its faces' winding faces, so the projection
    runs the layout's way round and no mirror is needed), with the world z axis projected as up (the y axis where
    z lies within 45° of ``n``: a piece lying in x, y) and ``up × n`` across, as a drawing's views are laid out:
    a wall comes up the right way, a piece in x, y keeps its x and y; the angle of least squares (orthogonal Procrustes,
    each vertex weighted by a third of its triangles' 3D areas). 0 where the mesh has no front (a closed-up
    tube's vector area under 1e-3 of its area) or the layout has collapsed."""
    p = vertices[faces]
    normals = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]) / 2
    areas = np.linalg.norm(normals, axis=1)
    front = normals.sum(axis=0)
    if not np.linalg.norm(front) > 1e-3 * areas.sum():
        return 0.0
    n = front / np.linalg.norm(front)
    axis = np.eye(3)[2 if abs(n[2]) <= math.sqrt(0.5) else 1]
    up = axis - (axis @ n) * n
    up /= np.linalg.norm(up)
    seen = vertices @ np.column_stack([np.cross(up, n), up])
    weight = np.bincount(faces.ravel(), weights=np.repeat(areas / 3, 3), minlength=len(vertices))
    a = layout - np.average(layout, axis=0, weights=weight)
    b = seen - np.average(seen, axis=0, weights=weight)
    # numpy's own sums, not BLAS's dot: a threaded dot splits the sum by the threads it has, and the pattern
    # files would differ in their last bits between a Dask worker (one BLAS thread) and the command
    cross = float(np.sum(weight * (a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0])))
    dot = float(np.sum(weight * (a[:, 0] * b[:, 0] + a[:, 1] * b[:, 1])))
    return math.atan2(cross, dot) if cross or dot else 0.0


def grain_note(drawing: PatternDrawing) -> str | None:
    """A grain whose pieces on the pattern agree less than :data:`GRAIN_AGREEMENT`: its line is their average,
    which the piece follows nowhere well. (A direction close to the surface's normal over much of it does that,
    and so does one along a cone's slope, whose lines fan out as the cone unrolls into a sector.)"""
    if not drawing.grain or drawing.grain_agreement >= GRAIN_AGREEMENT:
        return None
    return (f"the grain direction {drawing.grain} lies on the pattern in pieces that point many ways (agreement "
            f"{drawing.grain_agreement:.2f} of 1): the grain line drawn is their average, which much of the piece "
            "does not follow; a direction that runs along the surface, not across it, gives a truer line")


def run_caption(status: str, iterations: int, area_error: float, shape_error: float, folded: int,
                crossings: int | None = None, turned: int | None = None) -> str:
    """The line under the name on each sheet; ``crossings``: pairs of the boundary's sides that meet (a cut
    line that crosses itself, on a pattern with no fold), ``turned``: holes the pattern wraps over
    (:func:`golden_model.mesh.turned_holes`), each said when there are any."""
    return (f"{status} after {plural(iterations, 'iteration')}: E_S {error_text(area_error)}, "
            f"E_C {error_text(shape_error)}, "
            f"{folded} folded" + (f", its boundary crosses itself {'once' if crossings == 1 else f'{crossings} times'}"
                                         if crossings else "")
            + (f", it wraps over {turned} of its holes" if turned else ""))


#: How springflat's own OBJ files begin (a pattern's ``.obj``, a layout's ``.flat.obj``): an existing non-empty
#: ``.obj`` that does not is a mesh (a scan named as the output, or reached through a link), which no output
#: replaces. (``save_obj``'s default line, ``# written by springflat``, heads meshes too: the shipped scans.)
OWN_OBJ_HEADERS = (b"# springflat ",)


def check_not_a_mesh(path: Path, what: str = "--out") -> None:
    """Refuse an OBJ output over an existing non-empty regular file that springflat did not write
    (:data:`OWN_OBJ_HEADERS`)."""
    path = path if isinstance(path, Path) else Path(path)
    if path.suffix.lower() != ".obj":
        return
    target = output_target(path)
    try:
        if not stat.S_ISREG(os.stat(target).st_mode):
            return  # (not a file to replace: check_output_path says what it is)
        with open(target, "rb") as existing:
            head = existing.read(max(map(len, OWN_OBJ_HEADERS)))
    except OSError:
        return  # missing, or unreadable: the write says why
    if head and not head.startswith(OWN_OBJ_HEADERS):
        shown = f"'{path}'" + (f" (a link to '{target}')" if path.is_symlink() else "")
        raise PatternError(f"{what} {shown} is an OBJ file springflat did not write (a mesh?): it replaces only its "
                           "own patterns and layouts; remove it, or name another file")


def write_pattern_file(path: Path, drawing: PatternDrawing, *, paper: str = DEFAULT_PAPER,
                       dxf_edges: bool = False, turn: bool = True) -> None:
    """Write ``drawing`` to ``path`` in the format its ending names (:func:`pattern_kind`); on sheets (PDF, SVG)
    turned where that takes fewer (:func:`turned_to_fit`; ``turn=False``, or a drawing with a grain: as laid)."""
    kind = pattern_kind(path)
    if paper not in PAPERS:
        raise PatternError(f"paper must be one of {', '.join(PAPERS)}, got {paper!r}")
    check_not_a_mesh(path, "the pattern file")
    if kind == "flat.obj":
        with atomic_write(path) as tmp:
            save_obj(tmp, drawing.layout, drawing.faces,
                     f"springflat layout of '{drawing.name}': x, y in {drawing.units}, z = 0")
    elif kind == "flat.svg":
        write_layout(path, drawing.layout, drawing.faces, vertices=drawing.vertices, units=drawing.units)
    elif kind == "obj":
        with atomic_write(path) as tmp:
            _write_uv_obj(tmp, drawing)
    elif kind == "dxf":
        with atomic_write(path) as tmp:
            _write_dxf(tmp, drawing, dxf_edges)
    else:
        plan = None
        if turn and not drawing.grain:  # (a grain fixes the pattern's turn)
            drawing, plan = _turned_to_fit(drawing, paper)
        size = pattern_size_mm(drawing)
        check_sheet_count(size, paper, drawing.units)
        if plan is None:
            plan = _printed_sheets(drawing, paper)[0]  # (within MAX_SHEETS: checked above)
        with atomic_write(path) as tmp:
            (_write_pdf if kind == "pdf" else _write_svg)(tmp, drawing, plan)


# --------------------------------------------------------------------------- OBJ with vt


def uv_coordinates(layout: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """``(uv, origin, size)``: ``uv = (layout - origin) / size`` in [0, 1]², aspect kept.

    ``origin`` is the layout's lower-left corner and ``size`` its larger side (in the layout's units), so
    ``uv * size + origin`` gives the pattern back.
    """
    layout = np.asarray(layout, dtype=np.float64)
    origin = layout.min(axis=0)
    size = float(np.max(layout.max(axis=0) - origin)) or 1.0
    return (layout - origin) / size, origin, size


def _write_uv_obj(path: str, drawing: PatternDrawing) -> None:
    uv, origin, size = uv_coordinates(drawing.layout)
    faces = np.asarray(drawing.faces, dtype=np.int64) + 1
    with open(path, "w", encoding="utf-8") as out:
        out.write(f"# springflat pattern of '{drawing.name}': v = the 3D mesh in {drawing.units}, "
                  "vt = the flattened pattern\n")
        x0, y0, scale = float(origin[0]), float(origin[1]), float(size)  # repr: the shortest exact decimal
        out.write(f"# vt = (x - {x0!r}, y - {y0!r}) / {scale!r}: the pattern scaled into [0, 1]; "
                  f"multiply by {scale!r} {drawing.units} for its true size\n")
        if drawing.caption:
            out.write(f"# {drawing.caption}\n")
        np.savetxt(out, drawing.vertices, fmt="v %.17g %.17g %.17g")
        np.savetxt(out, uv, fmt="vt %.17g %.17g")
        np.savetxt(out, np.repeat(faces, 2, axis=1), fmt="f %d/%d %d/%d %d/%d")


# --------------------------------------------------------------------------- DXF


def _write_dxf(path: str, drawing: PatternDrawing, edges: bool) -> None:
    import ezdxf
    from ezdxf import zoom

    previous = ezdxf.options.write_fixed_meta_data_for_testing
    ezdxf.options.write_fixed_meta_data_for_testing = True  # no dates or GUIDs: the same input, the same bytes
    try:
        doc = ezdxf.new("R2010", units=DXF_INSUNITS[drawing.units])
        doc.layers.add("CUT", color=7)
        msp = doc.modelspace()
        for loop in drawing.cut_loops:
            msp.add_lwpolyline(loop.tolist(), format="xy", close=True, dxfattribs={"layer": "CUT"})
        if drawing.seam > 0:
            on, off = (length / check_units(drawing.units) for length in SEW_DASH_MM)
            doc.linetypes.add("SEW", pattern=[on + off, on, -off], description="sew line")
            doc.layers.add("SEW", color=3, linetype="SEW")
            for loop in drawing.edge_loops:
                msp.add_lwpolyline(loop.tolist(), format="xy", close=True, dxfattribs={"layer": "SEW"})
        if edges:
            doc.layers.add("MESH", color=8)
            for a, b in drawing.layout[drawing.edges].tolist():
                msp.add_line(a, b, dxfattribs={"layer": "MESH"})
        if drawing.grain:
            doc.layers.add("GRAIN", color=5)
            for stroke in grain_arrow(drawing.grain_line()):
                msp.add_lwpolyline(stroke.tolist(), format="xy", dxfattribs={"layer": "GRAIN"})
        # the drawing's extents: ezdxf leaves them at ±1e20 ("not set"), and a viewer's "zoom extents" then
        # shows nothing useful; both the header and the model space are set (ezdxf copies the latter on save,
        # unless it is the origin)
        drawn = np.vstack([drawing.layout if edges else drawing.boundary_points, drawing.cut_points])
        low, high = (*drawn.min(axis=0), 0.0), (*drawn.max(axis=0), 0.0)
        msp.dxf.extmin, msp.dxf.extmax = low, high
        doc.header["$EXTMIN"], doc.header["$EXTMAX"] = low, high
        zoom.window(msp, low[:2], high[:2])  # the file opens showing the pattern
        meta = doc.ezdxf_metadata()
        meta["springflat_mesh"] = drawing.name
        meta["springflat_units"] = drawing.units
        if drawing.caption:
            meta["springflat_run"] = drawing.caption
        if drawing.grain:
            meta["springflat_grain"] = drawing.grain
        if drawing.seam > 0:
            meta["springflat_seam_allowance"] = f"{drawing.seam:.12g} {drawing.units}"
        # ezdxf adds a CLASS per object type in use while saving, in the order of a set (the hash seed's):
        # register them first, sorted, so that the file does not depend on the process
        for dxftype in sorted(doc.entitydb.dxf_types_in_use()):
            doc.classes.add_class(dxftype)
        doc.saveas(path)
    finally:
        ezdxf.options.write_fixed_meta_data_for_testing = previous


# --------------------------------------------------------------------------- sheets


@dataclass(frozen=True)
class Sheet:
    """One sheet of a tiled pattern.

    Attributes:
        label: row letter (A at the top) and column number (1 at the left), e.g. ``B2``.
        row: 0 at the bottom (math orientation); ``col``: 0 at the left.
        offset: ``(x, y)`` mm: the pattern point (in :func:`pattern_size_mm`'s frame, after
            :attr:`SheetPlan.shift`) at the window's lower-left corner.
    """

    label: str
    row: int
    col: int
    offset: tuple[float, float]


@dataclass(frozen=True)
class SheetPlan:
    """How a pattern of ``size`` mm goes onto sheets of ``page`` mm.

    Attributes:
        paper: ``a4``, ``letter`` or ``fit``; ``landscape`` when turned.
        page: ``(width, height)`` of a sheet, mm.
        window: ``(x, y, width, height)`` mm of the pattern's window on each sheet.
        rows, cols: the grid.
        shift: ``(x, y)`` mm added to the pattern so that it sits centred on the grid of windows.
        overlap: mm shared by adjacent windows.
        sheets: row by row from the top, each left to right (the grid's, less the blank ones).
        blank: sheets of the grid left out, as nothing of the pattern falls in their window.
    """

    paper: str
    landscape: bool
    page: tuple[float, float]
    window: tuple[float, float, float, float]
    rows: int
    cols: int
    shift: tuple[float, float]
    overlap: float
    sheets: tuple[Sheet, ...]
    blank: int = 0

    @property
    def stride(self) -> tuple[float, float]:
        """Distance between the lower-left corners of adjacent windows, mm."""
        return self.window[2] - self.overlap, self.window[3] - self.overlap

    def describe(self) -> str:
        if self.paper == "fit":
            return f"one {self.page[0]:.0f} x {self.page[1]:.0f} mm page"
        paper = PAPER_SHEETS[self.paper][0] + (" landscape" if self.landscape else " portrait")
        if len(self.sheets) == 1:
            return f"one {paper} sheet"
        blank = f", {self.blank} blank left out" if self.blank else ""
        columns, rows = (f"{n} {word}{'s' if n != 1 else ''}" for n, word in ((self.cols, "column"), (self.rows, "row")))
        return (f"{len(self.sheets)} {paper} sheets ({columns} x {rows}{blank}, "
                f"overlap {self.overlap:g} mm)")


def pattern_size_mm(drawing: PatternDrawing) -> tuple[float, float]:
    """Width and height of the pattern on paper at 1:1 (with its seam allowance), mm."""
    drawn = drawing.drawn_points
    extent = (drawn.max(axis=0) - drawn.min(axis=0)) * check_units(drawing.units)
    return float(extent[0]), float(extent[1])


#: How much smaller a ``fit`` page must be for :func:`turned_to_fit` to turn the pattern (a share of its area).
FIT_TURN_GAIN = 0.01


def turned_to_fit(drawing: PatternDrawing, paper: str) -> PatternDrawing:
    """``drawing`` turned on the sheets (a rotation about its centre, never a mirror) along the side of its
    convex hull whose box takes the fewest sheets of ``paper`` (``fit``: the smallest page, within a PDF's), if
    that prints fewer sheets than the layout as laid (blank ones left out; ``fit``: a page smaller by
    :data:`FIT_TURN_GAIN` of its area, or one where the laid page is too large). A box of least area has a
    side on the hull (Freeman and Shapira, 1975); the fewest sheets need not, so this is the best of those
    sides, never worse than as laid. The drawing's own frame, which the DXF and the OBJs keep, is the mesh's
    view (:meth:`PatternDrawing.as_seen`): a strip modelled at a slant lies as it was."""
    return _turned_to_fit(drawing, paper)[0]


def _turned_to_fit(drawing: PatternDrawing, paper: str) -> tuple[PatternDrawing, SheetPlan | None]:
    """:func:`turned_to_fit`'s drawing, with its sheets where the choice counted them (else ``None``): finding
    the blank sheets of a large pattern takes as long as the rest of its choice."""
    from scipy.spatial import ConvexHull, QhullError

    try:
        hull = drawing.layout[ConvexHull(drawing.layout).vertices]
    except (QhullError, ValueError):  # a layout on a line has no hull (it is refused as degenerate before)
        return drawing, None
    sides = np.roll(hull, -1, axis=0) - hull
    scale = check_units(drawing.units)
    # a seam allowance adds itself on each side of every box: no need to outline each turn's cut line
    grown = 2 * drawing.seam * (1 + SEAM_MARGIN)

    def box_cost(angle: float) -> tuple[float, float]:
        """(sheets of the grid, or the fit page's area; the box's area): what the hull turned by ``angle`` takes."""
        width, height = ((np.ptp(_turned(hull, angle, 0.0), axis=0) + grown) * scale).tolist()
        page, _, _, rows, cols = _grid((width, height), paper, OVERLAP_MM)
        if paper == "fit":
            return (page[0] * page[1] if max(page) <= MAX_PAGE_MM else math.inf), 0.0
        return float(rows * cols), width * height

    best = min(-np.arctan2(sides[:, 1], sides[:, 0]), key=box_cost)
    kept, turned = box_cost(0.0)[0], box_cost(best)[0]
    if paper == "fit":
        if not turned < (1 - FIT_TURN_GAIN) * kept:
            return drawing, None
        return replace(drawing, layout=_turned(drawing.layout, best, _centre(drawing.layout))), None
    if not turned < kept:
        return drawing, None
    candidate = replace(drawing, layout=_turned(drawing.layout, best, _centre(drawing.layout)))
    (turned_plan, turned_sheets), (laid_plan, laid_sheets) = (_printed_sheets(d, paper) for d in (candidate, drawing))
    # past MAX_SHEETS both: the turned one, on the smaller grid, is the size the refusal names
    return (candidate, turned_plan) if turned_sheets < laid_sheets or laid_sheets == math.inf else (drawing, laid_plan)


def _centre(points: np.ndarray) -> np.ndarray:
    return (points.max(axis=0) + points.min(axis=0)) / 2


def _turned(points: np.ndarray, angle: float, centre) -> np.ndarray:
    """``points`` rotated by ``angle`` (radians, anticlockwise) about ``centre``."""
    c, s = math.cos(angle), math.sin(angle)
    return (points - centre) @ np.array([[c, s], [-s, c]]) + centre


def _printed_sheets(drawing: PatternDrawing, paper: str) -> tuple[SheetPlan | None, float]:
    """The sheets of ``paper`` that print ``drawing`` (blank ones left out) and their number; ``(None,
    infinity)`` past :data:`MAX_SHEETS`."""
    size = pattern_size_mm(drawing)
    if _sheet_count(size, paper) > MAX_SHEETS:
        return None, math.inf
    plan = without_blank_sheets(plan_sheets(size, paper), drawing)
    return plan, len(plan.sheets)


def scale_note(drawing: PatternDrawing, units_option: str = "--units {}") -> str | None:
    """A note when the pattern is so small (under :data:`SMALL_PATTERN_MM`) or so large (over
    :data:`LARGE_PATTERN_MM`) at 1:1 that ``units`` is likely wrong, else ``None``; ``units_option`` spells
    the option that sets it (the API's ``units='{}'``)."""
    width, height = pattern_size_mm(replace(drawing, seam=0.0))  # the pattern's size, not the allowance chosen
    if SMALL_PATTERN_MM <= max(width, height) <= LARGE_PATTERN_MM:
        return None
    small = max(width, height) < SMALL_PATTERN_MM
    likely = [units for units in ("m", "cm", "in", "mm")
              if (UNIT_MM[units] > UNIT_MM[drawing.units]) == small and units != drawing.units]
    said = (f"the pattern is {width:.3g} x {height:.3g} mm" if small else
            f"the pattern is {width / 1000:.3g} x {height / 1000:.3g} m") + \
        f" at 1:1 with {units_option.format(drawing.units)}"
    if not likely:  # metres or millimetres: no larger or smaller unit to suggest
        return said
    names = [UNIT_NAMES[units] for units in likely]
    options = [units_option.format(units) for units in likely]
    return f"{said}: if the mesh is in {_either(names)}, say so with {_either(options)}"


def _either(words: list[str]) -> str:
    """``a``, ``a or b``, ``a, b or c``."""
    return words[0] if len(words) == 1 else f"{', '.join(words[:-1])} or {words[-1]}"


def error_text(error: float) -> str:
    """E_S or E_C as printed: four decimals, or three significant digits once the value is 10,000 or more
    (a diverged run's 1e300 is not 300 digits)."""
    return f"{error:.4f}" if abs(error) < 1e4 or not math.isfinite(error) else f"{error:.3g}"


def count_text(count: int) -> str:
    """A count as a person reads it: ``1,234``, or ``3.2e+17`` past a million (not 300 digits)."""
    if count < 10**6:
        return f"{count:,}"
    try:
        return f"{float(count):.2g}"
    except OverflowError:  # past float's range
        return f"about 10^{len(str(count)) - 1}"


def check_sheet_count(size: tuple[float, float], paper: str, units: str) -> None:
    """Refuse a print of more than :data:`MAX_SHEETS` sheets, or a ``fit`` page with a side above
    :data:`MAX_PAGE_MM` (a wrong ``--units``, most likely)."""
    page, _, _, rows, cols = _grid(size, paper, OVERLAP_MM)
    if rows * cols > MAX_SHEETS:
        raise PatternError(f"the pattern is {size[0] / 1000:.3g} x {size[1] / 1000:.3g} m at 1:1 with --units "
                           f"{units}: {count_text(rows * cols)} {paper} sheets (at most {MAX_SHEETS}); check --units, "
                           "or write .dxf")
    if max(page) > MAX_PAGE_MM:
        raise _page_too_large(f"the pattern is {size[0] / 1000:.3g} x {size[1] / 1000:.3g} m", units, size)


def _page_too_large(what: str, units: str, size: tuple[float, float]) -> PatternError:
    """The refusal of a ``fit`` page above :data:`MAX_PAGE_MM`, ``what`` the size that shows it; the papers it
    suggests are those that print a pattern of ``size`` mm in at most :data:`MAX_SHEETS` sheets."""
    tiled = [paper for paper in PAPER_MM if _sheet_count(size, paper) <= MAX_SHEETS]
    remedy = f"print it tiled (--paper {_either(tiled)}), " if tiled else ""
    return PatternError(f"{what} at 1:1 with --units {units}: a page larger than a PDF's {MAX_PAGE_MM / 1000:.3g} m "
                        f"a side (an SVG's pages are the PDF's); check --units, {remedy}or write .dxf")


def check_mesh_fits(mesh: Mesh, units: str, paper: str, seam: float = 0.0) -> None:
    """Refuse, before a run, a print that will need more than :data:`MAX_SHEETS` sheets whatever the layout.

    A pattern covers about the mesh's area (its area error E_S aside), and a seam allowance of ``seam`` (in
    ``units``) about its edge's length times the allowance (less where the edge is concave or jagged): half of
    that over one window's area is a lower bound of the sheets needed, the half taking up that excess.
    """
    area = float(mesh.face_areas.sum()) + seam * loop_length(mesh.vertices[mesh.boundary_loop])
    area_mm2 = area * check_units(units) ** 2
    if paper == "fit":  # the pattern's box holds about the mesh's area: its longer side is at least √area
        if math.sqrt(area_mm2) > MAX_PAGE_MM:
            side = math.sqrt(area_mm2) / 1000
            raise _page_too_large(f"the mesh's area is about {side:.3g} x {side:.3g} m", units, (side * 1000,) * 2)
        return
    page, _, window, _, _ = _grid((0.0, 0.0), paper, OVERLAP_MM)
    least = 0.5 * area_mm2 / (window[2] * window[3])
    if least > MAX_SHEETS:
        side = math.sqrt(area_mm2) / 1000
        raise PatternError(f"the mesh's area is about {side:.3g} x {side:.3g} m at 1:1 with --units {units}: more "
                           f"than {MAX_SHEETS} {paper} sheets; check --units, or write .dxf")


def _sheet_count(size: tuple[float, float], paper: str) -> int:
    """The sheets of ``paper`` a pattern of ``size`` mm takes (:func:`plan_sheets`)."""
    _, _, _, rows, cols = _grid(size, paper, OVERLAP_MM)
    return rows * cols


def _tiles(length: float, window: float, overlap: float) -> int:
    if length <= window:
        return 1
    return 1 + math.ceil((length - window) / (window - overlap) - 1e-9)


def _grid(size: tuple[float, float], paper: str, overlap: float):
    """``(page, landscape, window, rows, cols)`` of the fewest sheets (see :func:`plan_sheets`)."""
    width, height = size
    if paper == "fit":
        window = (max(width + 2 * FIT_PAD_MM, FIT_MIN_WIDTH_MM - 2 * MARGIN_MM), height + 2 * FIT_PAD_MM)
        choices = [((window[0] + 2 * MARGIN_MM, window[1] + 2 * MARGIN_MM + TITLE_MM), False)]
    elif paper in PAPER_MM:
        w, h = PAPER_MM[paper]
        choices = [((w, h), False), ((h, w), True)]
    else:
        raise PatternError(f"paper must be one of {', '.join(PAPERS)}, got {paper!r}")
    best = None
    for page, landscape in choices:
        window = (MARGIN_MM, MARGIN_MM + TITLE_MM, page[0] - 2 * MARGIN_MM, page[1] - 2 * MARGIN_MM - TITLE_MM)
        cols, rows = _tiles(width, window[2], overlap), _tiles(height, window[3], overlap)
        if best is None or rows * cols < best[3] * best[4]:
            best = (page, landscape, window, rows, cols)
    return best


def plan_sheets(size: tuple[float, float], paper: str = "a4", overlap: float = OVERLAP_MM) -> SheetPlan:
    """Lay a pattern of ``size`` = ``(width, height)`` mm onto sheets of ``paper`` (:data:`PAPERS`).

    A4 and Letter: portrait or landscape, whichever needs fewer sheets (portrait on a tie); the grid of
    windows is centred on the pattern.  ``fit``: one page, the pattern plus :data:`FIT_PAD_MM` around it.
    """
    page, landscape, window, rows, cols = _grid(size, paper, overlap)
    if rows * cols > MAX_SHEETS:
        raise PatternError(f"a pattern of {size[0] / 1000:.3g} x {size[1] / 1000:.3g} m needs {count_text(rows * cols)} "
                           f"{paper} sheets, more than {MAX_SHEETS}")
    sx, sy = window[2] - overlap, window[3] - overlap
    covered = (window[2] + (cols - 1) * sx, window[3] + (rows - 1) * sy)
    shift = ((covered[0] - size[0]) / 2, (covered[1] - size[1]) / 2)
    sheets = tuple(Sheet(f"{_row_name(rows - 1 - r)}{c + 1}", r, c, (c * sx, r * sy))
                   for r in reversed(range(rows)) for c in range(cols))
    return SheetPlan(paper, landscape, page, window, rows, cols, shift, overlap, sheets)


def without_blank_sheets(plan: SheetPlan, drawing: PatternDrawing) -> SheetPlan:
    """``plan`` less the sheets whose window holds nothing of the pattern (no triangle meets it: the cut
    line, mesh edges and folded triangles all lie on the triangles; with a seam allowance, the area inside the
    cut line, which holds them and the allowance): an L-shaped pattern's empty corner is not printed. The
    others keep their labels, so that the grid still shows where each goes."""
    from matplotlib.path import Path as Outline
    from matplotlib.transforms import Bbox

    if len(plan.sheets) == 1:
        return plan
    nodes = _pattern_mm(drawing, plan)
    corners = nodes[drawing.faces]  # (F, 3, 2)
    low_corner, high_corner = corners.min(axis=1), corners.max(axis=1)
    size = np.array(plan.window[2:])

    def drawn(sheet: Sheet) -> bool:
        low = np.array(sheet.offset)
        high = low + size
        if np.all((nodes >= low) & (nodes <= high), axis=1).any():  # a node in the window
            return True
        # else a triangle meets the window only if its box does and it crosses or covers the window
        near = np.flatnonzero(np.all((low_corner <= high) & (high_corner >= low), axis=1))
        window = Bbox([low, high])
        return any(Outline(np.vstack([corners[t], corners[t][:1]]), closed=True).intersects_bbox(window, filled=True)
                   for t in near)  # (a closed path's last vertex is not drawn)

    if drawing.seam > 0:  # the area inside the cut line, which holds the triangles and the allowance
        import shapely

        loops = [_pattern_mm(drawing, plan, loop) for loop in drawing.cut_loops]
        cut = edge_polygon(loops)
        kept = tuple(sheet for sheet in plan.sheets
                     if cut.intersects(shapely.box(*sheet.offset, *np.add(sheet.offset, size))))
    else:
        kept = tuple(sheet for sheet in plan.sheets if drawn(sheet))
    return replace(plan, sheets=kept, blank=len(plan.sheets) - len(kept))


def _row_name(index: int) -> str:
    """A, B, ..., Z, AA, AB, ... for row 0, 1, ..."""
    name = ""
    index += 1
    while index:
        index, rest = divmod(index - 1, 26)
        name = chr(ord("A") + rest) + name
    return name


def nice_length(limit: float) -> float:
    """The largest 1, 2 or 5 x 10^k not above ``limit`` (> 0)."""
    power = 10.0 ** math.floor(math.log10(limit))
    return max(step * power for step in (1.0, 2.0, 5.0) if step * power <= limit * (1 + 1e-12))


def scale_bar(units: str) -> tuple[float, float]:
    """``(length in units, length in mm)`` of the scale bar: the longest round length up to
    :data:`SCALE_BAR_MAX_MM` on paper."""
    per_unit = check_units(units)
    length = nice_length(SCALE_BAR_MAX_MM / per_unit)
    return length, length * per_unit


# --------------------------------------------------------------------------- drawing primitives (page mm)


@dataclass(frozen=True)
class Stroke:
    """A polyline on a sheet, mm; ``grey`` 0 = black; ``dash`` mm on, off, ... or ``None``; ``name`` its SVG class."""

    points: tuple[tuple[float, float], ...]
    width: float
    grey: float = 0.0
    dash: tuple[float, ...] | None = None
    name: str | None = None


@dataclass(frozen=True)
class Label:
    """Text on a sheet: ``(x, y)`` mm of its baseline; ``anchor`` start, middle or end."""

    x: float
    y: float
    text: str
    size: float = FONT_MM
    anchor: str = "start"
    bold: bool = False
    name: str | None = None


def _text_width(text: str, size: float, bold: bool = False) -> float:
    """Width in mm of ``text`` set in Helvetica (SVG: Helvetica or Arial, the same widths) of cap height
    ``size`` mm; a character beyond Latin-1, which Helvetica lacks and a viewer draws in another font, is
    counted 1 em, about its widest."""
    from reportlab.pdfbase.pdfmetrics import stringWidth

    em = size / CAP_HEIGHT_EM
    latin = "".join(c for c in text if ord(c) < 256)
    return stringWidth(latin, "Helvetica-Bold" if bold else "Helvetica", em) + (len(text) - len(latin)) * em


def _shortened_middle(text: str, cut: int) -> str:
    """``text`` with ``cut`` characters taken from its middle and ``...`` in their place."""
    keep = max(len(text) - cut, 2)
    return text[:(keep + 1) // 2] + "..." + text[len(text) - keep // 2:]


def _fitted(text: str, room: float, size: float, bold: bool = False,
            shorter: Callable[[int], str] | None = None) -> tuple[str, float]:
    """``(text, size)`` that fit in ``room`` mm: ``text`` as it is, or set smaller (down to
    :data:`MIN_TEXT_SCALE` of ``size``), or shortened at that size by ``shorter(n)`` (``n`` characters
    fewer, the fewest that fit; default: cut at the end, ``...`` in their place)."""
    width = _text_width(text, size, bold)
    if width <= room:
        return text, size
    smaller = size * room / width
    if smaller >= MIN_TEXT_SCALE * size:
        return text, smaller * (1 - 1e-9)  # rounding must not put it over the edge
    smallest = MIN_TEXT_SCALE * size
    shorter = shorter or (lambda n: text[:max(len(text) - n, 1)] + "...")
    low, high = 1, len(text)  # shorter(high) is as short as it gets; bisect for the fewest cut that fits
    while low < high:
        middle = (low + high) // 2
        if _text_width(shorter(middle), smallest, bold) <= room:
            high = middle
        else:
            low = middle + 1
    return shorter(low), smallest


def pattern_title(drawing: PatternDrawing, name: str | None = None) -> str:
    """The first line of every sheet, the PDF's and the SVG's title: the name (or ``name``), scale, units."""
    seam = f", seam allowance {length_text(drawing.seam, drawing.units)} included" if drawing.seam > 0 else ""
    return (f"{drawing.name if name is None else name}: springflat cutting pattern, scale 1:1, units "
            f"{drawing.units}{seam}")


def sheet_marks(plan: SheetPlan, sheet: Sheet, drawing: PatternDrawing) -> tuple[list[Stroke], list[Label]]:
    """The frame, overlap marks, title block and scale bar of one sheet, in page mm."""
    x0, y0, w, h = plan.window
    sx, sy = plan.stride
    strokes = [Stroke(((x0, y0), (x0 + w, y0), (x0 + w, y0 + h), (x0, y0 + h), (x0, y0)), 0.15, 0.55, name="frame")]
    labels: list[Label] = []
    by_place = {(s.row, s.col): s for s in plan.sheets}
    cross = 3.0

    def mark(a: tuple[float, float], b: tuple[float, float], neighbour: Sheet, at: tuple[float, float], anchor: str):
        strokes.append(Stroke((a, b), 0.2, GUIDE_GREY, dash=GUIDE_DASH_MM, name=f"overlap-{neighbour.label}"))
        for px, py in (a, b):
            strokes.append(Stroke(((px - cross, py), (px + cross, py)), 0.2, 0.0))
            strokes.append(Stroke(((px, py - cross), (px, py + cross)), 0.2, 0.0))
        labels.append(Label(at[0], at[1], f"{neighbour.label} overlaps here", 2.4, anchor))

    r, c = sheet.row, sheet.col
    if (r, c + 1) in by_place:  # the right neighbour's window starts at x0 + sx
        mark((x0 + sx, y0), (x0 + sx, y0 + h), by_place[(r, c + 1)], (x0 + sx - 1.0, y0 + h / 2), "end")
    if (r, c - 1) in by_place:
        mark((x0 + plan.overlap, y0), (x0 + plan.overlap, y0 + h), by_place[(r, c - 1)],
             (x0 + plan.overlap + 1.0, y0 + h / 2), "start")
    if (r + 1, c) in by_place:
        mark((x0, y0 + sy), (x0 + w, y0 + sy), by_place[(r + 1, c)], (x0 + w / 2, y0 + sy - 3.5), "middle")
    if (r - 1, c) in by_place:
        mark((x0, y0 + plan.overlap), (x0 + w, y0 + plan.overlap), by_place[(r - 1, c)],
             (x0 + w / 2, y0 + plan.overlap + 1.5), "middle")

    # title block: name and units, the run across the window; the sheet and how to print it at the left,
    # the scale bar at the right; a line too long for its room is set smaller, then shortened
    length, length_mm = scale_bar(drawing.units)
    bar_label = length_text(length, drawing.units)
    right = x0 + w
    bar_room = max(length_mm, _text_width(bar_label, 0.9 * FONT_MM))
    left_room = w - bar_room - TEXT_GAP_MM
    top = y0 - 5.0
    title, size = _fitted(pattern_title(drawing), w, FONT_MM, True,
                          lambda n: pattern_title(drawing, _shortened_middle(drawing.name, n)))
    labels.append(Label(x0, top, title, size, bold=True, name="title"))
    if drawing.caption:
        caption, size = _fitted(drawing.caption, w, 0.8 * FONT_MM)
        labels.append(Label(x0, top - 1.5 * FONT_MM, caption, size))
    where = f"sheet {sheet.label} of {len(plan.sheets)}: " if len(plan.sheets) > 1 else ""
    for row, (text, name) in enumerate(((f"{where}{plan.describe()}", "sheet"),
                                        ("print at 100 % (no fit to page) and measure the scale bar", None)), 3):
        text, size = _fitted(text, left_room, 0.8 * FONT_MM)
        labels.append(Label(x0, top - 1.5 * (row - 1) * FONT_MM, text, size, name=name))
    bar_y = MARGIN_MM + 3.0
    strokes.append(Stroke(((right - length_mm, bar_y), (right, bar_y)), 0.5, name="scale-bar"))
    for x in (right - length_mm, right):
        strokes.append(Stroke(((x, bar_y - 1.5), (x, bar_y + 1.5)), 0.3))
    labels.append(Label(right - length_mm / 2, bar_y + 2.5, bar_label, 0.9 * FONT_MM, "middle", name="scale-label"))
    return strokes, labels


def _median_edge_mm(drawing: PatternDrawing) -> float:
    p = drawing.layout[drawing.edges]
    return float(np.median(np.linalg.norm(p[:, 1] - p[:, 0], axis=1))) * check_units(drawing.units)


def _pattern_mm(drawing: PatternDrawing, plan: SheetPlan, points: np.ndarray | None = None) -> np.ndarray:
    """``points`` (in ``units``; by default the layout) in mm, shifted onto the grid of windows with the drawing
    (the layout and its cut line)."""
    points = drawing.layout if points is None else points
    return (points - drawing.drawn_points.min(axis=0)) * check_units(drawing.units) + np.array(plan.shift)


def _grain_mm(drawing: PatternDrawing, plan: SheetPlan) -> list[np.ndarray]:
    """The grain line's strokes (:func:`grain_arrow`) in the grid's mm, as :func:`_pattern_mm` places the
    pattern; none without a grain."""
    if not drawing.grain:
        return []
    return [_pattern_mm(drawing, plan, stroke) for stroke in grain_arrow(drawing.grain_line())]


def _pattern_parts(drawing: PatternDrawing, plan: SheetPlan
                   ) -> tuple[np.ndarray, np.ndarray, list[np.ndarray], list[np.ndarray]]:
    """``(edges (E', 2, 2), folded faces (K, 3, 2), the cut line's loops [(B, 2), ...], the sew line's loops
    [(B', 2), ...])`` in the grid's mm; no edges when they would merge on paper (median under
    :data:`EDGE_MIN_MM`); a sew line (the outer edge's and each kept hole's loop) where there is a seam
    allowance, else none."""
    q = _pattern_mm(drawing, plan)
    edges = q[drawing.edges] if _median_edge_mm(drawing) >= EDGE_MIN_MM else np.empty((0, 2, 2))
    folded = q[drawing.faces[folded_faces(drawing.layout, drawing.faces)]]
    cut = [_pattern_mm(drawing, plan, loop) for loop in drawing.cut_loops]
    sew = [_pattern_mm(drawing, plan, loop) for loop in drawing.edge_loops] if drawing.seam > 0 else []
    return edges, folded, cut, sew


def piece_label(drawing: PatternDrawing, plan: SheetPlan) -> Label | None:
    """The piece's name on the piece, in the grid's mm (so that it stays on the piece once the sheets are
    trimmed away): centred on the point inside the pattern farthest from its edge (shapely's ``polylabel``),
    as tall as fits in the circle there, up to :data:`PIECE_LABEL_MAX_MM`; ``None`` where it would be smaller
    than :data:`PIECE_LABEL_MIN_MM`."""
    import shapely
    from shapely.ops import polylabel

    area = shapely.make_valid(edge_polygon([_pattern_mm(drawing, plan, loop) for loop in drawing.edge_loops]))
    for stroke in _grain_mm(drawing, plan):  # beside the grain line, which runs through the piece's middle
        area = area.difference(shapely.LineString(stroke).buffer(GRAIN_CLEARANCE_MM))
    parts = [part for part in getattr(area, "geoms", [area]) if part.geom_type == "Polygon" and not part.is_empty]
    if not parts:
        return None
    largest = max(parts, key=lambda part: part.area)
    centre = polylabel(largest, tolerance=max(0.01, 1e-4 * math.sqrt(largest.area)))
    room = largest.boundary.distance(centre)  # the largest circle about the centre inside the piece
    name = drawing.name
    aspect = _text_width(name, 1.0)  # width per mm of cap height
    # the box about the centre: the name's width, and its cap height plus a descender's depth below it
    size = min(PIECE_LABEL_MAX_MM, 0.9 * 2 * room / math.hypot(aspect, 1.0 + 2 * DESCENDER_EM / CAP_HEIGHT_EM))
    if size < PIECE_LABEL_MIN_MM:
        return None
    return Label(centre.x, centre.y - size / 2, name, size, "middle", name="piece-label")


# --------------------------------------------------------------------------- PDF (reportlab)


def _closed_path(canvas, points: np.ndarray):
    """A reportlab path round the closed polygon ``points`` (page mm)."""
    path = canvas.beginPath()
    path.moveTo(*points[0])
    for point in points[1:].tolist():
        path.lineTo(*point)
    path.close()
    return path


def _write_pdf(path: str, drawing: PatternDrawing, plan: SheetPlan) -> None:
    """One page per sheet; the pattern is one form XObject, placed and clipped on each page.

    The page's user space is scaled to millimetres, so every coordinate below is in mm.
    """
    from reportlab.pdfgen.canvas import Canvas

    canvas = Canvas(path, pagesize=(plan.page[0] * PT_PER_MM, plan.page[1] * PT_PER_MM), invariant=1,
                    pageCompression=1, pdfVersion=(1, 6))  # 1.6: /PrintScaling below
    canvas.setTitle(pattern_title(drawing))
    canvas.setAuthor("springflat")
    canvas.setCreator("springflat")
    canvas.setSubject(f"{plan.describe()}; {drawing.caption}" if drawing.caption else plan.describe())
    canvas.setViewerPreference("PrintScaling", "None")  # the print dialog offers 100 %, not "fit to page"

    edges, folded, cut, sew = _pattern_parts(drawing, plan)
    sx, sy = plan.stride
    grid = (plan.window[2] + (plan.cols - 1) * sx, plan.window[3] + (plan.rows - 1) * sy)
    canvas.beginForm("pattern", -PT_PER_MM, -PT_PER_MM, (grid[0] + 1) * PT_PER_MM, (grid[1] + 1) * PT_PER_MM)
    canvas.scale(PT_PER_MM, PT_PER_MM)
    canvas.setLineCap(1)
    canvas.setLineJoin(1)
    if len(edges):
        path_ = canvas.beginPath()
        for (ax, ay), (bx, by) in edges.tolist():
            path_.moveTo(ax, ay)
            path_.lineTo(bx, by)
        canvas.setLineWidth(EDGE_WIDTH_MM)
        canvas.setStrokeGray(0.6)
        canvas.drawPath(path_, stroke=1, fill=0)
    if len(folded):
        path_ = canvas.beginPath()
        for triangle in folded.tolist():
            path_.moveTo(*triangle[0])
            path_.lineTo(*triangle[1])
            path_.lineTo(*triangle[2])
            path_.close()
        canvas.setFillGray(0.0)
        canvas.drawPath(path_, stroke=0, fill=1)
    canvas.setLineWidth(CUT_WIDTH_MM)
    canvas.setStrokeGray(0.0)
    for loop in cut:
        canvas.drawPath(_closed_path(canvas, loop), stroke=1, fill=0)
    if sew:
        canvas.setLineWidth(SEW_WIDTH_MM)
        canvas.setDash(list(SEW_DASH_MM))
        for loop in sew:
            canvas.drawPath(_closed_path(canvas, loop), stroke=1, fill=0)
        canvas.setDash([])
    grain = _grain_mm(drawing, plan)
    if grain:
        path_ = canvas.beginPath()
        for stroke in grain:
            path_.moveTo(*stroke[0])
            for point in stroke[1:].tolist():
                path_.lineTo(*point)
        canvas.setLineWidth(GRAIN_WIDTH_MM)
        canvas.setStrokeGray(GRAIN_GREY)
        canvas.drawPath(path_, stroke=1, fill=0)
    label = piece_label(drawing, plan)
    if label is not None:
        canvas.setFillGray(GRAIN_GREY)
        canvas.setFont("Helvetica", label.size / CAP_HEIGHT_EM)
        canvas.drawCentredString(label.x, label.y, label.text)
    canvas.endForm()

    x0, y0, w, h = plan.window
    for sheet in plan.sheets:
        canvas.scale(PT_PER_MM, PT_PER_MM)
        canvas.saveState()
        clip = canvas.beginPath()
        clip.rect(x0, y0, w, h)
        canvas.clipPath(clip, stroke=0, fill=0)
        canvas.translate(x0 - sheet.offset[0], y0 - sheet.offset[1])
        canvas.scale(1 / PT_PER_MM, 1 / PT_PER_MM)  # the form scales itself to mm
        canvas.doForm("pattern")
        canvas.restoreState()
        strokes, labels = sheet_marks(plan, sheet, drawing)
        for stroke in strokes:
            canvas.setLineWidth(stroke.width)
            canvas.setStrokeGray(stroke.grey)
            canvas.setDash(list(stroke.dash) if stroke.dash else [])
            line = canvas.beginPath()
            line.moveTo(*stroke.points[0])
            for point in stroke.points[1:]:
                line.lineTo(*point)
            canvas.drawPath(line, stroke=1, fill=0)
        canvas.setFillGray(0.0)
        for label in labels:
            canvas.setFont("Helvetica-Bold" if label.bold else "Helvetica", label.size / CAP_HEIGHT_EM)
            draw = {"start": canvas.drawString, "middle": canvas.drawCentredString,
                    "end": canvas.drawRightString}[label.anchor]
            draw(label.x, label.y, label.text)
        canvas.showPage()
    canvas.save()


# --------------------------------------------------------------------------- SVG


def _svg_num(value: float) -> str:
    text = f"{value:.4f}".rstrip("0").rstrip(".")
    return "0" if text in ("", "-0") else text


def _svg_points(points: Sequence[Sequence[float]], height: float, dx: float = 0.0, dy: float = 0.0) -> str:
    """``x,y`` pairs in SVG's frame (y down) of page-mm points."""
    return " ".join(f"{_svg_num(x + dx)},{_svg_num(height - (y + dy))}" for x, y in points)


def _write_svg(path: str, drawing: PatternDrawing, plan: SheetPlan) -> None:
    """All sheets in one SVG, user unit = 1 mm; each sheet a ``<g id="sheet-LABEL">`` at its place in the grid.

    The pattern is drawn once in ``<defs>`` (y flipped) and placed on each sheet by ``<use>`` inside the
    window's clip path.  ``sodipodi:namedview`` declares each sheet as an Inkscape page, so that Inkscape
    prints or exports them one per page.
    """
    page_w, page_h = plan.page
    total_w = plan.cols * page_w + (plan.cols - 1) * SVG_GAP_MM
    total_h = plan.rows * page_h + (plan.rows - 1) * SVG_GAP_MM
    edges, folded, cut, sew = _pattern_parts(drawing, plan)
    x0, y0, w, h = plan.window
    title = pattern_title(drawing)

    def place(sheet: Sheet) -> tuple[float, float]:
        return sheet.col * (page_w + SVG_GAP_MM), (plan.rows - 1 - sheet.row) * (page_h + SVG_GAP_MM)

    with open(path, "w", encoding="utf-8") as out:
        write = out.write
        write('<?xml version="1.0" encoding="UTF-8"?>\n')
        write('<svg xmlns="http://www.w3.org/2000/svg" xmlns:xlink="http://www.w3.org/1999/xlink" '
              'xmlns:inkscape="http://www.inkscape.org/namespaces/inkscape" '
              'xmlns:sodipodi="http://sodipodi.sourceforge.net/DTD/sodipodi-0.dtd" '
              f'width="{_svg_num(total_w)}mm" height="{_svg_num(total_h)}mm" '
              f'viewBox="0 0 {_svg_num(total_w)} {_svg_num(total_h)}">\n')
        write(f"<title>{escape(title)}</title>\n")
        write(f"<desc>{escape(plan.describe())}; 1 user unit = 1 mm on paper"
              f"{'; ' + escape(drawing.caption) if drawing.caption else ''}</desc>\n")
        write('<sodipodi:namedview id="pages">\n')
        for sheet in plan.sheets:
            px, py = place(sheet)
            write(f'<inkscape:page id="page-{sheet.label}" inkscape:label="{sheet.label}" x="{_svg_num(px)}" '
                  f'y="{_svg_num(py)}" width="{_svg_num(page_w)}" height="{_svg_num(page_h)}"/>\n')
        write("</sodipodi:namedview>\n<defs>\n")
        write(f'<clipPath id="window" clipPathUnits="userSpaceOnUse"><rect x="{_svg_num(x0)}" '
              f'y="{_svg_num(page_h - y0 - h)}" width="{_svg_num(w)}" height="{_svg_num(h)}"/></clipPath>\n')
        # the pattern in the grid's mm, y flipped about 0: <use> translates it by (dx, page_h - dy)
        write('<g id="pattern" fill="none" stroke-linecap="round" stroke-linejoin="round">\n')
        if len(edges):
            d = "".join(f"M{_svg_num(ax)} {_svg_num(-ay)}L{_svg_num(bx)} {_svg_num(-by)}"
                        for (ax, ay), (bx, by) in edges.tolist())
            write(f'<path id="mesh-edges" d="{d}" stroke="#999999" stroke-width="{_svg_num(EDGE_WIDTH_MM)}"/>\n')
        if len(folded):
            write('<g id="folded" fill="#000000" stroke="none">\n')
            for triangle in folded.tolist():
                write(f'<polygon points="{_svg_points(triangle, 0.0)}"/>\n')
            write("</g>\n")
        for k, loop in enumerate(cut):  # the outer loop, then the holes: kept ones, or the allowance's
            name = 'id="cut"' if k == 0 else 'class="cut-hole"'
            write(f'<polygon {name} points="{_svg_points(loop.tolist(), 0.0)}" stroke="#000000" '
                  f'stroke-width="{_svg_num(CUT_WIDTH_MM)}"/>\n')
        for k, loop in enumerate(sew):  # the outer edge, then the kept holes' edges
            name = 'id="sew"' if k == 0 else 'class="sew-hole"'
            write(f'<polygon {name} points="{_svg_points(loop.tolist(), 0.0)}" stroke="#000000" '
                  f'stroke-width="{_svg_num(SEW_WIDTH_MM)}" '
                  f'stroke-dasharray="{" ".join(_svg_num(length) for length in SEW_DASH_MM)}"/>\n')
        grain, grey = _grain_mm(drawing, plan), round(255 * GRAIN_GREY)
        if grain:
            write(f'<g id="grain" stroke="#{grey:02x}{grey:02x}{grey:02x}" '
                  f'stroke-width="{_svg_num(GRAIN_WIDTH_MM)}">\n')
            for stroke in grain:
                write(f'<polyline points="{_svg_points(stroke.tolist(), 0.0)}"/>\n')
            write("</g>\n")
        label = piece_label(drawing, plan)
        if label is not None:
            write(f'<text class="{label.name}" x="{_svg_num(label.x)}" y="{_svg_num(-label.y)}" stroke="none" '
                  f'fill="#{grey:02x}{grey:02x}{grey:02x}" font-family="Helvetica, Arial, sans-serif" '
                  f'font-size="{_svg_num(label.size / CAP_HEIGHT_EM)}" text-anchor="middle">{escape(label.text)}'
                  '</text>\n')
        write("</g>\n</defs>\n")
        for sheet in plan.sheets:
            px, py = place(sheet)
            write(f'<g id="sheet-{sheet.label}" transform="translate({_svg_num(px)} {_svg_num(py)})">\n')
            write(f'<rect width="{_svg_num(page_w)}" height="{_svg_num(page_h)}" fill="#ffffff" '
                  f'stroke="{"#cccccc" if len(plan.sheets) > 1 else "none"}" stroke-width="0.2"/>\n')
            dx, dy = x0 - sheet.offset[0], y0 - sheet.offset[1]
            write(f'<g clip-path="url(#window)"><use xlink:href="#pattern" '
                  f'transform="translate({_svg_num(dx)} {_svg_num(page_h - dy)})"/></g>\n')
            strokes, labels = sheet_marks(plan, sheet, drawing)
            for stroke in strokes:
                grey = round(255 * stroke.grey)
                dashes = " ".join(_svg_num(length) for length in stroke.dash or ())
                attributes = (f' class="{stroke.name}"' if stroke.name else "") + (
                    f' stroke-dasharray="{dashes}"' if dashes else "")
                write(f'<polyline points="{_svg_points(stroke.points, page_h)}" fill="none" '
                      f'stroke="#{grey:02x}{grey:02x}{grey:02x}" stroke-width="{_svg_num(stroke.width)}"'
                      f'{attributes}/>\n')
            for label in labels:
                anchor = "" if label.anchor == "start" else f' text-anchor="{label.anchor}"'
                weight = ' font-weight="bold"' if label.bold else ""
                ident = f' class="{label.name}"' if label.name else ""
                write(f'<text x="{_svg_num(label.x)}" y="{_svg_num(page_h - label.y)}" '
                      f'font-family="Helvetica, Arial, sans-serif" font-size="{_svg_num(label.size / CAP_HEIGHT_EM)}"'
                      f'{anchor}{weight}{ident}>{escape(label.text)}</text>\n')
            write("</g>\n")
        write("</svg>\n")
