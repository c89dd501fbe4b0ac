"""The knobs of a study (signal classes, LUT, rsqrt, rounding) and the configurations they make."""

from __future__ import annotations

import json
from dataclasses import dataclass
from typing import Any, Iterable, Sequence

from ..fixed.format import Rounding
from ..fixed.formats_set import CONTROLLER_FIELDS, FORMAT_FIELDS, FormatSet
from ..modes import Step
from ..params import FlattenParams, ParameterError

SIGNAL_CLASSES: dict[str, tuple[str, ...]] = {
    "position": ("position", "delta", "face_edge"),
    "velocity": ("velocity",),
    "length_sq": ("length_sq",),
    "rsqrt": ("rsqrt",),
    "rest_length": ("rest_length", "error_acc", "face_area"),
    "spring": ("spring",),
    "force": ("force", "force_acc"),
    "inv_mass": ("inv_mass",),
    "accel": ("accel",),
    "dt": ("dt", "lut_entry"),
    "half_dt_sq": ("half_dt_sq",),
    "error": ("error", "reciprocal"),
    "damping": ("damping",),
    "area": ("area",),
    "barrier": ("barrier_gain", "barrier_coeff"),
    "power": ("power", "power_acc"),
}
"""Signal classes whose fraction bits are swept: name -> tied format fields.

All fields of a class shift by the same number of fraction bits (their offsets
in the base set are kept); the class's value is the first field's fraction bits.
"""
assert sorted(f for fs in SIGNAL_CLASSES.values() for f in fs) == sorted(FORMAT_FIELDS)

def unexercised_classes(params: Iterable[FlattenParams]) -> tuple[str, ...]:
    """The signal classes that no run with one of ``params`` reads, so whose fraction bits change no result:
    ``area`` and ``barrier`` without the fold barrier, ``power`` (the momentum restart's) without the momentum
    dynamics, ``damping`` where the paper dynamics' ``1 − γ`` is 1 exactly (no damping). The optimiser leaves
    them at the base's widths: bits taken off there would save nothing the study measured."""
    params = list(params)
    used = {"area": any(p.barrier for p in params), "barrier": any(p.barrier for p in params),
            "power": any(p.mode.step is Step.MOMENTUM for p in params),
            "damping": any(p.mode.has_masses and p.damping != 0 for p in params)}
    return tuple(cls for cls in SIGNAL_CLASSES if not used.get(cls, True))


DATAPATH_FIELDS: tuple[str, ...] = tuple(f for f in FORMAT_FIELDS
                                         if f not in ("error", "lut_entry") + CONTROLLER_FIELDS)
"""Formats of the node datapath counted by ``total_bits`` (the step generator's and the controller's are not)."""

OTHER_KNOB_VALUES: dict[str, tuple[Any, ...]] = {
    "lut_index_bits": (4, 5, 6, 7, 10, 12),
    "lut_interpolate": (True, False),
    "rsqrt_seed_bits": (4, 6, 8, 10, 12, 14),
    "rsqrt_newton_steps": (0, 1, 2),
    "rounding": tuple(r.value for r in Rounding),
}
"""Values tried by the sweep of each non-format knob (the base's value is skipped)."""

KNOBS: tuple[str, ...] = tuple(SIGNAL_CLASSES) + tuple(OTHER_KNOB_VALUES)
"""Everything ``--sweep`` accepts (``frac`` selects every signal class)."""

DEFAULT_BITS = (8, 24, 4)
"""Fraction bits a signal-class sweep tries by default: ``range(8, 24 + 1, 4)``."""

DEFAULT_STRIDES = (1, 2, 4, 8)
"""Fraction bits one optimiser move may remove from a signal class."""


def parse_bits(text: str) -> tuple[int, int, int]:
    """``"MIN:MAX"`` or ``"MIN:MAX:STEP"`` -> ``(min, max, step)``; ParameterError otherwise."""
    parts = str(text).split(":")
    try:
        if len(parts) not in (2, 3):
            raise ValueError
        lo, hi = int(parts[0]), int(parts[1])
        step = int(parts[2]) if len(parts) == 3 else 1
    except ValueError:
        raise ParameterError(f"--bits expects MIN:MAX or MIN:MAX:STEP (integers), got '{text}'") from None
    if not 0 <= lo <= hi <= 60 or step < 1:
        raise ParameterError(f"--bits {text}: need 0 <= MIN <= MAX <= 60 and STEP >= 1")
    return lo, hi, step


def parse_knobs(text: str | Sequence[str] | None) -> list[str]:
    """A comma list of knobs (``all``, ``frac``, ``none`` allowed) -> knob names in :data:`KNOBS` order."""
    if text is None:
        return list(KNOBS)
    items = [t.strip() for t in (text.split(",") if isinstance(text, str) else text) if t.strip()]
    if not items:
        raise ParameterError("--sweep: empty knob list (use 'none' for no sweep)")
    if len(items) > 1 and "none" in (item.lower() for item in items):
        raise ParameterError(f"--sweep {','.join(items)}: 'none' sweeps nothing: give it alone, or drop it")
    chosen: set[str] = set()
    for item in items:
        low = item.lower()
        if low == "none":
            continue
        if low == "all":
            chosen.update(KNOBS)
        elif low == "frac":
            chosen.update(SIGNAL_CLASSES)
        elif low in KNOBS:
            chosen.add(low)
        else:
            raise ParameterError(f"--sweep: unknown knob '{item}'; expected all, none, frac or some of "
                                 f"{', '.join(KNOBS)}")
    return [k for k in KNOBS if k in chosen]


@dataclass(frozen=True)
class Config:
    """One configuration of a study: a FormatSet, or the reason it could not be built."""

    label: str
    fs: FormatSet | None
    kind: str = "sweep"  # base | preset | sweep | optimiser | chosen
    knob: str = ""
    value: Any = ""
    error: str = ""

    @property
    def key(self) -> str | None:
        return None if self.fs is None else fs_key(self.fs)


def fs_key(fs: FormatSet) -> str:
    """Identity of a FormatSet's contents (name and notes ignored)."""
    d = fs.to_dict()
    d.pop("name", None)
    d.pop("notes", None)
    return json.dumps(d, sort_keys=True)


def class_frac_bits(fs: FormatSet, cls: str) -> int:
    """A signal class's fraction bits (its first field's)."""
    return getattr(fs, SIGNAL_CLASSES[cls][0]).frac_bits


def class_changes(fs: FormatSet, cls: str, bits: int) -> dict[str, str]:
    """Format changes that give class ``cls`` ``bits`` fraction bits (tied fields shift with it)."""
    shift = bits - class_frac_bits(fs, cls)
    changes = {}
    for f in SIGNAL_CLASSES[cls]:
        fmt = getattr(fs, f)
        if fmt.frac_bits + shift < 0:
            raise ValueError(f"{f} would have {fmt.frac_bits + shift} fraction bits")
        changes[f] = f"{'s' if fmt.signed else 'u'}{fmt.int_bits}.{fmt.frac_bits + shift}"
    return changes


def make_config(base: FormatSet, label: str, kind: str = "sweep", knob: str = "", value: Any = "",
                **changes: Any) -> Config:
    """``base`` with ``changes``; a refused combination becomes a Config with ``error`` set."""
    try:
        fs = base.replace(name=label, notes={}, **changes)
    except ValueError as exc:
        return Config(label, None, kind, knob, value, str(exc).splitlines()[0])
    return Config(label, fs, kind, knob, value)


def _knob_config(base: FormatSet, knob: str, value: Any, kind: str = "sweep", label: str | None = None) -> Config:
    label = label or f"{knob}={value}"
    if knob in SIGNAL_CLASSES:
        try:
            changes = class_changes(base, knob, int(value))
        except ValueError as exc:
            return Config(label, None, kind, knob, value, str(exc))
        return make_config(base, label, kind, knob, value, **changes)
    return make_config(base, label, kind, knob, value, **{knob: value})


def sweep_configs(base: FormatSet, knobs: Iterable[str] | None = None,
                  bits: tuple[int, int, int] = DEFAULT_BITS) -> list[Config]:
    """One-knob-at-a-time variations of ``base`` (values equal to the base's are skipped).

    Signal classes take the fraction bits ``range(bits[0], bits[1] + 1, bits[2])``;
    other knobs take :data:`OTHER_KNOB_VALUES`.  Refused combinations are
    included with their error message.
    """
    lo, hi, step = bits
    configs = []
    for knob in (KNOBS if knobs is None else knobs):
        if knob in SIGNAL_CLASSES:
            current = class_frac_bits(base, knob)
            values: Iterable[Any] = [b for b in range(lo, hi + 1, step) if b != current]
        elif knob in OTHER_KNOB_VALUES:
            current = getattr(base, knob)
            current = current.value if isinstance(current, Rounding) else current
            values = [v for v in OTHER_KNOB_VALUES[knob] if v != current]
        else:
            raise ParameterError(f"unknown knob '{knob}'")
        configs += [_knob_config(base, knob, v) for v in values]
    return configs


def preset_configs(base: FormatSet | None = None) -> list[Config]:
    """The presets, for comparison (the one equal to ``base`` is left out)."""
    out = []
    for name in FormatSet.presets():
        fs = FormatSet.preset(name)
        if base is not None and fs_key(fs) == fs_key(base):
            continue
        out.append(Config(f"preset:{name}", fs, "preset"))
    return out
