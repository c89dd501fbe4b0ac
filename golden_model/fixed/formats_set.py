"""The set of fixed-point formats and knobs of the per-node update pipeline.

A :class:`FormatSet` names one :class:`~golden_model.fixed.format.Format` per
signal class and the non-format knobs (rsqrt seed/Newton parameters, exp-LUT
size, default rounding).  Presets live as JSON in ``golden_model/data/formats/``
(the only place their values are written down); the RTL and the golden model
both take every width from the loaded object.

Validation (``__post_init__``) guarantees that every multiplication the golden
model forms in numpy int64 — the datapath's, the rsqrt unit's, the step
generator's and the controller's E_S cross products, all listed by
:meth:`FormatSet.products` — has an exact product that fits int64 (sum of operand
widths <= 63), that signals that are non-negative by construction use unsigned
formats, that the exp-LUT indexing fits the error format, and that the
controller's ``face_area`` holds every area its ``face_edge`` edges can span.
"""

from __future__ import annotations

import json
import math
import re
from dataclasses import MISSING, dataclass, field, fields, replace
from pathlib import Path
from typing import Any, NamedTuple

from ..files import read_regular_file
from .dsp import Operand
from .exp_table import lut_slope_bits
from .format import MAX_PRODUCT_WIDTH, MAX_WIDTH, Format, Rounding
from .rsqrt import RsqrtConfig

__all__ = ["FormatSet", "FORMAT_FIELDS", "CONTROLLER_FIELDS", "PRESET_DIR", "Product", "UNITS", "KNOB_DOMAINS",
           "WIDENED_FIELDS", "accumulator_guard_bits", "RESOLUTION_SCALES", "ACCURACY_FACTOR"]

PRESET_DIR = Path(__file__).resolve().parent.parent / "data" / "formats"
"""Directory holding the preset JSON files (``<name>.json``)."""

FORMAT_FIELDS: tuple[str, ...] = (
    "position",
    "velocity",
    "delta",
    "rest_length",
    "length_sq",
    "rsqrt",
    "spring",
    "force",
    "force_acc",
    "inv_mass",
    "accel",
    "dt",
    "half_dt_sq",
    "error_acc",
    "error",
    "lut_entry",
    "damping",
    "area",
    "barrier_gain",
    "barrier_coeff",
    "power",
    "power_acc",
    "face_edge",
    "face_area",
    "reciprocal",
)
"""Names of the Format-valued fields, in pipeline order (the controller's last)."""

CONTROLLER_FIELDS: tuple[str, ...] = ("power_acc", "face_edge", "face_area", "reciprocal")
"""Formats of the controller around the RTL (``golden_model.fixed.engine``), not of the datapath."""

_SIGNED = ("position", "velocity", "delta", "spring", "force", "force_acc", "accel", "area", "power", "power_acc",
           "face_edge")
_UNSIGNED = (
    "rest_length", "length_sq", "rsqrt", "inv_mass", "dt", "half_dt_sq",
    "error_acc", "error", "lut_entry", "damping", "barrier_gain", "barrier_coeff", "face_area", "reciprocal",
)


#: Each knob's domain, inclusive: what the RTL builds and the golden model tabulates in bounded
#: time and memory (``docs/fixed-point.md`` states it). ``lut_index_bits`` is also at most
#: ``error``'s fraction bits.
KNOB_DOMAINS: dict[str, tuple[int, int]] = {
    "rsqrt_seed_bits": (2, 16),  # a seed ROM of 3·2^(b−2) entries: 49,152 at 16
    "rsqrt_newton_steps": (0, 4),  # one multiplier stage each; 4 take even a 2-bit seed to ~23 bits
    "lut_index_bits": (1, 12),  # an exp table of 2^b + 1 entries: 4,097 at 12
    "max_degree": (1, 1024),  # ceil(log2) guard bits in every accumulator: 10 at 1024
}

class FormatSetNotBuildable(ValueError):
    """An RTL component's refusal (``hdl``) of a format set that the golden model runs but the RTL cannot
    build: a velocity finer than the positions it is added to, a barrier longer than the rsqrt unit beside
    it, an operand wider than a DSP block's. Here, so that the command line and the API can catch it without
    importing Amaranth; the command line says it in one line, naming the format set."""


#: What a format set's ``name`` may hold: it names directories (``synth-ecp5-NAME``) and goes into the
#: exported Verilog, C header and reports, where a newline, a quote, ``*/`` or a ``/`` would break out of a
#: comment or a directory.  The study's labels (``position=12``, ``base:default``, ``opt-03``) and the
#: benchmarks' (``default, rsqrt u8.20, length_sq u7.28``) fit.
NAME_CHARACTERS = "letters, digits, inner spaces and . , _ : = + -"
NAME_PATTERN = re.compile(r"[A-Za-z0-9.,_:=+-]([A-Za-z0-9 .,_:=+-]{0,62}[A-Za-z0-9.,_:=+-])?")

#: Formats the datapath widens by one integer bit (the adder input of the position and
#: velocity updates, ``pipeline._wide``): they take at most ``MAX_WIDTH - 1`` bits.
WIDENED_FIELDS = ("position", "velocity")


#: The scale (in the host's units: mean edge lengths, unit time) at which each signal's rounding shows in
#: a run's result, for :meth:`FormatSet.resolution`: positions and lengths, ``r = 1/|Δ|``, the strain ``1 − d·r``
#: and the error measures near 1; forces about ``C/2`` (a quarter); the weights about 1/2; the
#: accelerations a tenth; velocities, ``Δt`` and the exp table's entries near the smallest step 0.01;
#: ``Δt²/2`` near 1e-3. Calibrated, with :data:`ACCURACY_FACTOR`, on random format sets
#: (``tests/golden_model/test_formats_property.py``; ``docs/fixed-point.md`` has the runs).
RESOLUTION_SCALES: dict[str, float] = {
    "position": 1.0, "rest_length": 1.0, "delta": 1.0, "length_sq": 1.0, "rsqrt": 1.0, "spring": 1.0, "error": 1.0,
    "force": 0.25, "force_acc": 0.25, "inv_mass": 0.5, "accel": 0.1,
    "velocity": 0.01, "dt": 0.01, "lut_entry": 0.01, "half_dt_sq": 1e-3,
}

#: A format set's documented accuracy: a run without saturation events ends with its E_S and E_C
#: within ``ACCURACY_FACTOR · resolution()`` of the float engine's (:meth:`FormatSet.accuracy_bound`).
ACCURACY_FACTOR = 4.0


def accumulator_guard_bits(max_degree: int) -> int:
    """Extra integer bits that let ``max_degree`` terms add up without overflow."""
    return max(1, math.ceil(math.log2(max_degree)))


UNITS = ("node_update", "rsqrt", "step_generator", "controller")
"""Where a product is computed: the RTL's node-update datapath, its rsqrt unit, the step
generator, or the controller around them (``golden_model.fixed.engine``; not in the RTL)."""


def _no_repeated_keys(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    """A JSON object, refusing a key given twice (json keeps the last silently: ``"max_degree": 32,
    "max_degree": 33`` would be 33)."""
    seen: dict[str, Any] = {}
    for key, value in pairs:
        if key in seen:
            raise ValueError(f"the key {key!r} is given twice")
        seen[key] = value
    return seen


def _json_kind(value: Any) -> str:
    """How a JSON value reads in a message: ``null``, ``the string "default"``, ``the number 42``, ..."""
    if value is None:
        return "null"
    if isinstance(value, bool):
        return f"the boolean {str(value).lower()}"
    if isinstance(value, (int, float)):
        return f"the number {value!r}"
    if isinstance(value, str):
        return f"the string {json.dumps(value[:40])}"
    return "a list" if isinstance(value, list) else f"a {type(value).__name__}"


class Product(NamedTuple):
    """One kind of multiplication: operands as the hardware holds them, instances, unit.

    ``int64``: the golden model forms the exact product in numpy int64, so the operand widths
    must sum to at most ``MAX_PRODUCT_WIDTH`` (checked when a :class:`FormatSet` is built).
    """

    name: str
    a: Operand
    b: Operand
    count: int = 1
    unit: str = "node_update"
    int64: bool = True


@dataclass(frozen=True)
class FormatSet:
    """Formats (one per signal class) and knobs of the fixed-point pipeline.

    Real-value meaning of each format field (mesh scaled so the mean edge is ~1):

    ``position`` P, ``velocity`` V, ``delta`` P_j - P_i after narrowing,
    ``rest_length`` d, ``length_sq`` |delta|**2 (rsqrt input), ``rsqrt`` r = 1/|delta|,
    ``spring`` s = C/2*(1 - d*r) (dimensionless), ``force`` per-neighbour s*delta,
    ``force_acc`` sum of forces, ``inv_mass`` 1/m, ``accel`` a, ``dt`` step,
    ``half_dt_sq`` dt**2/2, ``error_acc`` sums of |L - d|, ``error`` E_S/E_C in
    [0, 1] (LUT input), ``lut_entry`` exp-table entries 0.1*exp(-5(1-E)),
    ``damping`` the velocity factor 1 - gamma in (0, 1] (needs an integer bit
    so that gamma = 0 multiplies by exactly 1).  The momentum dynamics and
    the fold barrier (``docs/dynamics.md``): ``area`` a doubled signed 2D
    triangle area X and its threshold, ``barrier_gain`` the per-entry
    G = mu*C/(4*X*), ``barrier_coeff`` c = G*(threshold - X)+, ``power`` a node's
    F.V, ``power_acc`` their sum S; ``dt`` also carries the momentum beta_k and
    ``inv_mass`` the weights w_i = 2/(C*deg_i).  The controller's E_S and E_C
    (``golden_model.fixed.engine``): ``face_edge`` a triangle's edge P_b - P_a of the
    layout (narrowing only saturates when it has position's fraction bits, so the
    cross product is exact), ``face_area`` a triangle's area |A'| and the host's A
    (wide enough for every area of edges that fit ``face_edge``), ``reciprocal`` the
    mantissa of 1/total in [1, 2) (E = sum * mantissa * 2^-shift).

    Format fields accept ``"s3.16"``-style strings (converted on construction).
    """

    position: Format
    velocity: Format
    delta: Format
    rest_length: Format
    length_sq: Format
    rsqrt: Format
    spring: Format
    force: Format
    force_acc: Format
    inv_mass: Format
    accel: Format
    dt: Format
    half_dt_sq: Format
    error_acc: Format
    error: Format
    lut_entry: Format
    damping: Format
    area: Format
    barrier_gain: Format
    barrier_coeff: Format
    power: Format
    power_acc: Format
    face_edge: Format
    face_area: Format
    reciprocal: Format
    rsqrt_seed_bits: int
    rsqrt_newton_steps: int
    lut_index_bits: int
    lut_interpolate: bool
    rounding: Rounding = Rounding.HALF_UP
    max_degree: int = 32
    name: str = "custom"
    notes: dict[str, str] = field(default_factory=dict, compare=False, hash=False, repr=False)

    # ------------------------------------------------------------------ validation
    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not NAME_PATTERN.fullmatch(self.name):
            raise ValueError(f"the format set's name {self.name!r} must be 1 to 64 {NAME_CHARACTERS} (it names "
                             "the synthesis bundle and goes into the exported files)")
        for f in FORMAT_FIELDS:
            v = getattr(self, f)
            if not isinstance(v, Format):
                try:
                    v = Format.parse(v)
                except ValueError as exc:
                    raise ValueError(f"FormatSet {self.name!r}: field {f}: {exc}") from None
                object.__setattr__(self, f, v)
        try:
            object.__setattr__(self, "rounding", Rounding(self.rounding))
        except ValueError:
            raise ValueError(
                f"FormatSet {self.name!r}: unknown rounding {self.rounding!r}; "
                f"expected one of {[m.value for m in Rounding]}"
            ) from None
        for knob, (low, high) in KNOB_DOMAINS.items():
            v = getattr(self, knob)
            if isinstance(v, bool) or not isinstance(v, int):
                raise ValueError(f"FormatSet {self.name!r}: {knob} must be an int, got {v!r}")
            if not low <= v <= high:
                raise ValueError(f"FormatSet {self.name!r}: {knob} {v} is outside its domain {low}..{high}")
        for f in WIDENED_FIELDS:
            if getattr(self, f).width > MAX_WIDTH - 1:
                raise ValueError(f"FormatSet {self.name!r}: {f} {getattr(self, f)} is {getattr(self, f).width} bits; "
                                 f"its update adds in one more bit, so at most {MAX_WIDTH - 1}")
        if self.damping.int_bits < 1:
            raise ValueError(f"FormatSet {self.name!r}: damping {self.damping} needs an integer bit: 1 - gamma = 1 "
                             "(no damping, and the momentum dynamics) must be exact")
        if self.error_acc.frac_bits < self.rest_length.frac_bits:
            raise ValueError(f"FormatSet {self.name!r}: error_acc needs at least rest_length's fraction bits "
                             f"({self.rest_length.frac_bits}) so that error sums are exact")
        if not isinstance(self.lut_interpolate, bool):
            raise ValueError(f"FormatSet {self.name!r}: lut_interpolate must be a bool")
        self._check_signedness()
        self._check_step_path()
        self._check_controller()
        try:
            self.rsqrt_config()
        except ValueError as exc:
            raise ValueError(f"FormatSet {self.name!r}: {exc}") from None
        for p in self.products():
            wa, wb = p.a.width, p.b.width
            if p.int64 and wa + wb > MAX_PRODUCT_WIDTH:
                raise ValueError(
                    f"FormatSet {self.name!r}: product {p.name} needs {wa} + {wb} = {wa + wb} "
                    f"bits > {MAX_PRODUCT_WIDTH}; the exact product would not fit int64"
                )
        sums = {**{f"{k} accumulator": v for k, v in self.accumulators().items()}, **self.aligned_sums()}
        for name, (_, width) in sums.items():
            if width > MAX_PRODUCT_WIDTH:
                raise ValueError(f"FormatSet {self.name!r}: the {name} takes {width} bits > {MAX_PRODUCT_WIDTH}; "
                                 "its exact value would not fit int64")

    def _check_signedness(self) -> None:
        for f in _SIGNED:
            if not getattr(self, f).signed:
                raise ValueError(f"FormatSet {self.name!r}: {f} must be a signed format")
        for f in _UNSIGNED:
            if getattr(self, f).signed:
                raise ValueError(
                    f"FormatSet {self.name!r}: {f} is non-negative and must be unsigned"
                )

    def _check_step_path(self) -> None:
        n = self.name
        if self.error.int_bits > 1:
            raise ValueError(
                f"FormatSet {n!r}: error format {self.error} must be u0.F or u1.F (E in [0, 1])"
            )
        if not 1 <= self.lut_index_bits <= self.error.frac_bits:
            raise ValueError(
                f"FormatSet {n!r}: lut_index_bits {self.lut_index_bits} must be in "
                f"1..error.frac_bits ({self.error.frac_bits})"
            )

    def _check_controller(self) -> None:
        n = self.name
        for fmt, of in (("face_edge", "position"), ("face_area", "error_acc")):
            if getattr(self, fmt).frac_bits != getattr(self, of).frac_bits:
                raise ValueError(f"FormatSet {n!r}: {fmt} {getattr(self, fmt)} needs {of}'s fraction bits "
                                 f"({getattr(self, of).frac_bits}) so that E_S's areas and sums are exact")
        if self.face_area.int_bits < 2 * self.face_edge.int_bits:
            raise ValueError(
                f"FormatSet {n!r}: face_area {self.face_area} needs at least {2 * self.face_edge.int_bits} integer "
                f"bits to hold the area of every triangle whose edges fit face_edge {self.face_edge}"
            )
        if self.reciprocal.int_bits != 1 or self.reciprocal.frac_bits <= self.error.frac_bits:
            raise ValueError(
                f"FormatSet {n!r}: reciprocal {self.reciprocal} must be u1.F (a mantissa in [1, 2)) with more "
                f"fraction bits than error {self.error}"
            )

    # ------------------------------------------------------------------ derived
    @property
    def lut_frac_bits(self) -> int:
        """Bits of E below the LUT index (interpolation weight width)."""
        return self.error.frac_bits - self.lut_index_bits

    @property
    def interpolates(self) -> bool:
        """Whether the step generator interpolates (``lut_interpolate`` and E has bits below the index)."""
        return self.lut_interpolate and self.lut_frac_bits > 0

    def products(self) -> list[Product]:
        """Every multiplication of the design, one :class:`Product` per kind.

        Operands are as the hardware holds them (``hdl/`` builds each with
        :func:`~golden_model.fixed.dsp.dsp_partial_products`): the barrier's shortfall
        ``h >= 0`` drops the sign bit of ``area``; the LUT interpolation multiplies an entry
        difference (``lut_slope_bits`` wide) by the ``lut_frac_bits`` low bits of E; the
        rsqrt unit's first Newton step squares the seed (:meth:`RsqrtConfig.step_products`).
        ``count`` is the number of instances (x and y: 2; the step generator's two lookups: 2).
        The controller's (unit ``controller``, not in the RTL) come last; ``int64`` marks the
        products the golden model forms in numpy int64, whose widths ``__post_init__`` checks.
        """
        op = Operand.of
        delta = op(self.delta)
        shortfall = Format(False, self.area.int_bits, self.area.frac_bits)
        prods = [
            Product("delta*delta -> length_sq", delta, delta, 2),
            Product("delta*delta -> area (cross product)", delta, delta, 2),
            Product("barrier_gain*shortfall -> barrier_coeff", op(self.barrier_gain), op(shortfall)),
            Product("barrier_coeff*barrier_edge -> force", op(self.barrier_coeff), delta, 2),
            Product("rest_length*rsqrt (d*r)", op(self.rest_length), op(self.rsqrt)),
            Product("length_sq*rsqrt (L)", op(self.length_sq), op(self.rsqrt)),
            Product("spring*spring (1/2 C * u)", op(self.spring), op(self.spring)),
            Product("spring*delta -> force", op(self.spring), delta, 2),
            Product("force_acc*inv_mass -> accel", op(self.force_acc), op(self.inv_mass), 2),
            Product("force_acc*velocity -> power", op(self.force_acc), op(self.velocity), 2),
            Product("dt*velocity", op(self.dt), op(self.velocity), 2),
            Product("half_dt_sq*accel", op(self.half_dt_sq), op(self.accel), 2),
            Product("dt*accel", op(self.dt), op(self.accel), 2),
            Product("velocity*damping", op(self.velocity), op(self.damping), 2),
        ]
        cfg = self.rsqrt_config()
        for step in range(cfg.newton_steps):
            prods += [Product(f"rsqrt {name} (Newton step {step + 1})", op(fa), op(fb), 1, "rsqrt")
                      for name, fa, fb in cfg.step_products(step)]
        if self.interpolates:
            prods.append(Product("lut interpolation (entry diff * E low bits)",
                                 Operand(lut_slope_bits(self.lut_index_bits, self.lut_entry), False),
                                 Operand(self.lut_frac_bits, False), 2, "step_generator"))
        prods.append(Product("dt*dt -> half_dt_sq", op(self.dt), op(self.dt), 1, "step_generator"))
        # The controller: E_S's cross products of the layout's triangle edges (numpy int64, over
        # all triangles) and the normalisations of the E_S and E_C sums (one scalar each per
        # iteration, formed exactly as a Python int: 64 bits in the default set).
        prods += [
            Product("face_edge*face_edge -> face_area (E_S cross product)", op(self.face_edge), op(self.face_edge),
                    2, "controller"),
            Product("error_acc*reciprocal -> error (E_S, E_C normalisation)", op(self.error_acc),
                    op(self.reciprocal), 2, "controller", int64=False),
        ]
        return prods

    def accumulators(self) -> dict[str, tuple[bool, int]]:
        """``{name: (signed, width)}`` of the force pass's per-node sums, exact with
        :func:`accumulator_guard_bits` guard bits for ``max_degree`` entries (the RTL's
        accumulator widths; the golden model forms them in int64, so ``__post_init__`` checks
        each against ``MAX_PRODUCT_WIDTH``): ``force`` Σf (two terms per entry with the barrier),
        ``error`` Σ|L − d|, ``error_squares`` Σ|L − d|² and ``barrier_energy`` Σc·h (``c``, ``h`` ≥ 0)."""
        guard = accumulator_guard_bits(self.max_degree)
        coeff_bits = self.barrier_coeff.width - int(self.barrier_coeff.signed)
        return {"force": (True, self.force.width + 1 + guard),
                "error": (False, self.rest_length.width + guard),
                "error_squares": (False, 2 * self.rest_length.width + guard),
                "barrier_energy": (False, coeff_bits + self.area.width - 1 + guard)}

    def aligned_sums(self) -> dict[str, tuple[bool, int]]:
        """``{name: (signed, width)}`` of the sums of two products aligned to the finer fraction (the position
        step ``Δt·V + ½Δt²·a`` and the momentum step ``β·V + a``, ``pipeline.integrate*``): the
        wider aligned term plus a carry."""
        fv = self.dt.frac_bits + self.velocity.frac_bits
        wv = self.dt.width + self.velocity.width
        paper = (self.half_dt_sq.frac_bits + self.accel.frac_bits, self.half_dt_sq.width + self.accel.width)
        momentum = (self.accel.frac_bits, self.accel.width)
        return {name: (True, max(wv + max(fv, fa) - fv, wa + max(fv, fa) - fa) + 1)
                for name, (fa, wa) in (("position step", paper), ("momentum step", momentum))}

    def resolution(self) -> float:
        """``ρ = Σ 2^-F / m`` over :data:`RESOLUTION_SCALES` (each signal's lsb at the scale ``m`` where it
        shows), plus the rsqrt method's relative error (:meth:`RsqrtConfig.method_error`: few seed bits
        and Newton steps make ``r`` coarser than its lsb); twice that with ``floor`` rounding, whose
        error is up to a whole lsb and always of one sign (it drifts), against half an lsb either way."""
        rho = (sum(math.ldexp(1.0, -getattr(self, f).frac_bits) / m for f, m in RESOLUTION_SCALES.items())
               + self.rsqrt_config().method_error())
        return 2.0 * rho if self.rounding is Rounding.FLOOR else rho

    def accuracy_bound(self) -> float:
        """The documented bound on ``|ΔE_S|``, ``|ΔE_C|`` against the float engine of a run without saturation
        events: ``ACCURACY_FACTOR · resolution()`` (``docs/fixed-point.md``, "Every legal format set")."""
        return ACCURACY_FACTOR * self.resolution()

    def rsqrt_config(self) -> RsqrtConfig:
        """The rsqrt unit configuration: ``length_sq`` -> ``rsqrt``."""
        return RsqrtConfig(self.length_sq, self.rsqrt, self.rsqrt_seed_bits,
                           self.rsqrt_newton_steps)

    def formats(self) -> dict[str, Format]:
        """``{field name: Format}`` for all format fields."""
        return {f: getattr(self, f) for f in FORMAT_FIELDS}

    def replace(self, **changes: Any) -> FormatSet:
        """Copy with fields changed (formats may be given as strings); re-validated."""
        return replace(self, **changes)

    # ------------------------------------------------------------------ JSON
    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict (formats as strings); inverse of :meth:`from_dict`."""
        d: dict[str, Any] = {"name": self.name, "formats": {f: str(getattr(self, f))
                                                            for f in FORMAT_FIELDS}}
        for f in fields(self):
            if f.name not in FORMAT_FIELDS and f.name not in ("name", "notes"):
                v = getattr(self, f.name)
                d[f.name] = v.value if isinstance(v, Rounding) else v
        if self.notes:
            d["notes"] = dict(self.notes)
        return d

    def to_json(self, indent: int = 2) -> str:
        return json.dumps(self.to_dict(), indent=indent) + "\n"

    def save(self, path: str | Path) -> None:
        Path(path).write_text(self.to_json())

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> FormatSet:
        """Build from the JSON schema written by :meth:`to_dict` (unknown keys are errors)."""
        if not isinstance(d, dict):
            raise ValueError(f"a format set is a JSON object with 'formats' and the knobs, not {_json_kind(d)}")
        d = dict(d)
        name = d.pop("name", "custom")
        if not isinstance(name, str):
            raise ValueError(f"the format set's 'name' must be a string, not {_json_kind(name)}")
        fmts = d.pop("formats", None)
        if not isinstance(fmts, dict):
            raise ValueError(f"FormatSet {name!r}: missing 'formats' object")
        missing = set(FORMAT_FIELDS) - set(fmts)
        extra = set(fmts) - set(FORMAT_FIELDS)
        if missing or extra:
            raise ValueError(
                f"FormatSet {name!r}: formats missing {sorted(missing)}, unknown {sorted(extra)}"
            )
        notes = d.pop("notes", {})
        if not isinstance(notes, dict):
            raise ValueError(f"FormatSet {name!r}: 'notes' must be an object, not {_json_kind(notes)}")
        knobs = [f for f in fields(cls) if f.name not in FORMAT_FIELDS and f.name not in ("name", "notes")]
        unknown = set(d) - {f.name for f in knobs}
        if unknown:
            raise ValueError(f"FormatSet {name!r}: unknown keys {sorted(unknown)}")
        missing = [f.name for f in knobs if f.name not in d and f.default is MISSING]  # (rounding, max_degree:
        if missing:                                                                # defaults, docs/fixed-point.md)
            raise ValueError(f"FormatSet {name!r}: missing the knob{'s' if len(missing) > 1 else ''} "
                             f"{', '.join(missing)}")
        return cls(**fmts, **d, name=name, notes=dict(notes))

    @staticmethod
    def names_preset(path_or_preset: str | Path) -> bool:
        """Whether :meth:`load` reads ``path_or_preset`` as a preset name (a string without a directory
        part and without the suffix ``.json``), not as a file."""
        p = Path(path_or_preset)  # Path drops a leading './': the text itself must name no directory
        return (isinstance(path_or_preset, str) and p.suffix != ".json" and len(p.parts) == 1
                and "/" not in path_or_preset)

    @classmethod
    def load(cls, path_or_preset: str | Path) -> FormatSet:
        """Load a JSON file (a regular file: a FIFO or a device is refused with an :class:`OSError`, never
        opened), or a preset by name (``"default"``, ``"narrow"``)."""
        if cls.names_preset(path_or_preset):
            return cls.preset(str(path_or_preset))
        fs = cls.from_dict(json.loads(read_regular_file(path_or_preset), object_pairs_hook=_no_repeated_keys))
        if fs.name in cls.presets() and fs.content() != cls.preset(fs.name).content():  # (reports name the set)
            raise ValueError(f"it is named '{fs.name}', a preset's name, but its formats are not that preset's: give "
                             "it a name of its own (\"name\" in the file), so that its results are not taken for the "
                             "preset's")
        return fs

    def content(self) -> dict[str, Any]:
        """:meth:`to_dict` without the name and the notes: what the set computes with."""
        return {k: v for k, v in self.to_dict().items() if k not in ("name", "notes")}

    @classmethod
    def preset(cls, name: str) -> FormatSet:
        """Load ``golden_model/data/formats/<name>.json``."""
        p = PRESET_DIR / f"{name}.json"
        if not p.is_file():
            raise ValueError(f"unknown FormatSet preset {name!r}; available: {cls.presets()} (or a file: a path with "
                             "a directory part or ending in .json)")
        return cls.from_dict(json.loads(p.read_text()))

    @staticmethod
    def presets() -> list[str]:
        """Names of the available presets."""
        return sorted(p.stem for p in PRESET_DIR.glob("*.json"))

    def summary(self) -> str:
        """One line per format: name, format, width, real range, lsb."""
        lines = [f"FormatSet {self.name}"]
        for f, fmt in self.formats().items():
            lines.append(f"  {f:12s} {str(fmt):7s} {fmt.width:3d} b  "
                         f"[{fmt.min:.6g}, {fmt.max:.6g}]  lsb {fmt.lsb:.3g}")
        for k in ("rsqrt_seed_bits", "rsqrt_newton_steps", "lut_index_bits",
                  "lut_interpolate", "max_degree"):
            lines.append(f"  {k} = {getattr(self, k)}")
        lines.append(f"  rounding = {self.rounding.value}")
        return "\n".join(lines)
