"""sim/payloads.py: one beat (nested dicts through Layout.const) and many beats (numpy) give the same bits."""

import random

import numpy as np
import pytest
from amaranth.hdl import signed, unsigned
from amaranth.lib import data

from golden_model.fixed import FormatSet
from hdl.layouts import entry_layout, errors_layout, result_layout, step_layout
from sim.payloads import leaves, pack, pack_beats, unpack, unpack_beats
from support import PRESETS

LAYOUTS = {"entry": entry_layout, "result": result_layout, "step": step_layout, "errors": errors_layout}


def random_fields(layout, n, rng):
    """A nested dict with ``n`` random in-range values in every leaf."""
    fields = {}
    for path, _, width, is_signed in leaves(layout):
        lo, hi = (-(1 << (width - 1)), 1 << (width - 1)) if is_signed else (0, 1 << width)
        node = fields
        for name in path[:-1]:
            node = node.setdefault(name, {})
        node[path[-1]] = rng.integers(lo, hi, n)
    return fields


def beat(fields, k):
    """Beat ``k`` of a nested dict of arrays, as a nested dict of ints."""
    return {name: beat(value, k) if isinstance(value, dict) else int(value[k]) for name, value in fields.items()}


@pytest.mark.parametrize("preset", PRESETS)
@pytest.mark.parametrize("name", LAYOUTS)
def test_one_beat_and_many_beats_agree(preset, name):
    layout = LAYOUTS[name](FormatSet.preset(preset))
    fields = random_fields(layout, 200, np.random.default_rng(1))
    raw = pack_beats(layout, fields)
    assert raw == [pack(layout, beat(fields, k)) for k in range(200)]
    assert raw == [layout.const(beat(fields, k)).as_bits() for k in range(200)]
    assert [unpack(layout, r) for r in raw] == [beat(fields, k) for k in range(200)]
    back = unpack_beats(layout, raw)
    for path, *_ in leaves(layout):
        got, want = back, fields
        for key in path:
            got, want = got[key], want[key]
        assert got.dtype == np.int64
        np.testing.assert_array_equal(got, want)


def test_signed_fields_round_trip_and_missing_fields_are_zero():
    layout = data.StructLayout({"a": signed(5), "b": unsigned(3), "c": data.StructLayout({"x": signed(70)})})
    raw = pack(layout, {"a": -1, "c": {"x": -2}})
    assert raw == 0b11111 | ((1 << 70) - 2) << 8
    assert unpack(layout, raw) == {"a": -1, "b": 0, "c": {"x": -2}}
    assert pack_beats(layout, {"a": [-1, 3], "c": {"x": [-2, 5]}}) == [raw, 3 | 5 << 8]
    out = unpack_beats(layout, [raw, 3 | 5 << 8])
    np.testing.assert_array_equal(out["a"], [-1, 3])
    np.testing.assert_array_equal(out["b"], [0, 0])
    assert list(out["c"]["x"]) == [-2, 5]


def test_plain_shapes_are_one_leaf():
    assert pack(unsigned(8), 300) == 44 and pack(signed(8), -1) == 255
    assert unpack(signed(8), 255) == -1 and unpack(unsigned(8), 255) == 255
    assert pack_beats(signed(4), np.array([-1, 7])) == [15, 7]
    np.testing.assert_array_equal(unpack_beats(signed(4), [15, 7]), [-1, 7])


def test_unknown_fields_are_refused():
    layout = step_layout(FormatSet.preset("default"))
    with pytest.raises(ValueError, match="refers to key 'dtt'"):
        pack(layout, {"dtt": 1})
    with pytest.raises(ValueError, match="no leaf field dtt"):
        pack_beats(layout, {"dtt": [1]})


def test_wide_payloads_take_the_python_int_path():
    """Beats wider than int64 (the entry layout) and narrow ones (the step layout) round-trip alike."""
    rng = random.Random(2)
    for layout in (entry_layout(FormatSet.preset("default")), step_layout(FormatSet.preset("default"))):
        raw = [rng.getrandbits(layout.size) for _ in range(50)]
        assert pack_beats(layout, unpack_beats(layout, raw)) == raw
