"""RTL area pass (hdl.AreaError) against the golden model's ``area_sum``, in Amaranth's simulator.

The sum ``Σ|A − |A'||`` [error_acc] and the saturation events (``face_edge``, ``face_area``,
``area_sum``) of each pass are compared with what ``golden_model.fixed.measures.area_sum``
computes and counts (the sum ``area_error`` normalises). Triangles arrive with seeded random
gaps (the input is always ready).
"""

import gc
import warnings

import numpy as np
import pytest
from amaranth.hdl import UnusedElaboratable

from golden_model.fixed import FormatSet, SaturationCounter
from golden_model.fixed.measures import area_sum
from hdl.area_error import AreaError
from sim.payloads import pack_beats
from support import PRESETS
from support.streams import StreamRun, run_testbenches, stream_producer, top_level_verilog

SATURATION_NAMES = ("face_edge", "face_area", "area_sum")


def golden_pass(fs, corners, areas):
    """``(Σ|A − |A'|| [error_acc], {name: saturation events})`` of ``area_sum`` on triangles
    ``corners`` (F, 3, 2) raw [position] with host areas ``areas`` (F,) raw [face_area]."""
    n = len(corners)
    counter = SaturationCounter()
    total = area_sum(fs, np.arange(3 * n).reshape(n, 3), np.asarray(areas, dtype=np.int64),
                     np.asarray(corners, dtype=np.int64).reshape(-1, 2), counter)
    return total, {name: counter[name] for name in SATURATION_NAMES}


def triangle_beats(dut, corners, areas):
    corners = np.asarray(corners, dtype=np.int64)
    fields = {corner: {"x": corners[:, k, 0], "y": corners[:, k, 1]} for k, corner in enumerate("abc")}
    fields["area"] = np.asarray(areas, dtype=np.int64)
    return pack_beats(dut.i.payload.shape(), fields)


def simulate(dut, passes, *, seed=0, p_valid=1.0):
    """Each pass ``(corners, areas)`` after a one-clock ``clear``; returns per pass the sum, the
    saturation counts, and the edges from its last transfer until ``idle`` rose."""
    results = []

    async def bench(ctx):
        for index, (corners, areas) in enumerate(passes):
            ctx.set(dut.clear, 1)
            await ctx.tick()
            ctx.set(dut.clear, 0)
            run = StreamRun()
            await stream_producer(dut.i, triangle_beats(dut, corners, areas), run, seed=seed + index,
                                  p_valid=p_valid)(ctx)
            edges = 0
            while not ctx.get(dut.idle):
                await ctx.tick()
                edges += 1
                assert edges <= dut.latency + 1, "idle never rose"
            counts = ctx.get(dut.saturations)
            results.append((ctx.get(dut.total), {name: int(counts[name]) for name in SATURATION_NAMES}, edges))

    run_testbenches(dut, bench)
    return results


def check_passes(fs, passes, **kw):
    dut = AreaError(fs)
    results = simulate(dut, passes, **kw)
    for index, ((corners, areas), (total, counts, _)) in enumerate(zip(passes, results)):
        want_total, want_counts = golden_pass(fs, corners, areas)
        assert (total, counts) == (want_total, want_counts), f"pass {index}"
    return dut, results


def random_triangles(fs, n, rng, *, spread, area_max=16.0):
    """``n`` triangles: a random corner ``a`` anywhere in ``position``'s range and ``b``, ``c``
    within ``spread`` (a real length) of it, clipped to the range; random host areas up to
    ``area_max`` (real, at most ``face_area``'s max)."""
    pos = fs.position
    a = rng.integers(pos.raw_min, pos.raw_max + 1, size=(n, 1, 2))
    offsets = rng.integers(-int(spread * 2**pos.frac_bits), int(spread * 2**pos.frac_bits) + 1, size=(n, 2, 2))
    corners = np.clip(np.concatenate([a, a + offsets], axis=1), pos.raw_min, pos.raw_max)
    areas = rng.integers(0, min(int(area_max * 2**fs.face_area.frac_bits), fs.face_area.raw_max) + 1, n)
    return corners, areas


def extreme_triangles(fs):
    """Corners on the range's corners (the largest cross products, the longest edges; the sum
    saturates), degenerate ones, and host areas 0 and max."""
    lo, hi = fs.position.raw_min, fs.position.raw_max
    c = [(lo, lo), (hi, lo), (lo, hi), (hi, hi), (0, 0)]
    corners = np.array([[c[i], c[j], c[k]] for i in range(5) for j in range(5) for k in range(5)])
    areas = np.resize([0, fs.face_area.raw_max, fs.face_area.raw_max // 3], len(corners))
    return corners, areas


def triangles_summing_near(fs, target, n, rng):
    """``n`` ordinary triangles whose host areas make the exact sum about ``target`` [error_acc]."""
    corners, _ = random_triangles(fs, n, rng, spread=2)
    areas = np.full(n, min(target // n, fs.face_area.raw_max))
    return corners, areas


@pytest.mark.parametrize("preset", PRESETS)
def test_random_triangles_with_gaps(preset):
    """Ordinary, long (saturating face_edge in the default set) and extreme triangles, several
    passes with clears between them, one of them saturating the sum."""
    fs = FormatSet.preset(preset)
    rng = np.random.default_rng(1)
    passes = [
        random_triangles(fs, 300, rng, spread=4),
        random_triangles(fs, 300, rng, spread=2 * fs.face_edge.max, area_max=fs.face_area.max),
        extreme_triangles(fs),
        random_triangles(fs, 50, rng, spread=1),
    ]
    _, results = check_passes(fs, passes, seed=2, p_valid=0.6)
    counts = [c for _, c, _ in results]
    # the passes reach what they are there for (face_area never saturates: FormatSet makes it
    # wide enough for every area of face_edge edges)
    assert counts[0]["area_sum"] == 0 and results[0][0] > 0
    assert counts[2]["area_sum"] == 1
    if fs.face_edge.max < 2 * fs.position.max:  # default: edges longer than ±256 saturate
        assert counts[1]["face_edge"] > 0 and counts[2]["face_edge"] > 0


@pytest.mark.parametrize("preset", PRESETS)
def test_sum_at_and_just_past_error_acc_max(preset):
    """The sum's saturation: exactly ``raw_max`` is not an event, one lsb more is."""
    fs = FormatSet.preset(preset)
    rng = np.random.default_rng(3)
    top = fs.error_acc.raw_max
    corners, areas = triangles_summing_near(fs, top, 64, rng)
    # one more triangle with A = |A'| + the remainder: the exact sum hits raw_max, then raw_max + 1
    base, _ = golden_pass(fs, corners, areas)
    degenerate = np.zeros((1, 3, 2), dtype=np.int64)  # |A'| = 0: its term is its host area
    remainder = top - base
    assert 0 <= remainder <= fs.face_area.raw_max
    passes = [(np.concatenate([corners, degenerate]), np.r_[areas, remainder]),
              (np.concatenate([corners, degenerate]), np.r_[areas, remainder + 1]),
              # saturated, then terms of 0: the event stays counted
              (np.concatenate([corners, degenerate, np.zeros((3, 3, 2), dtype=np.int64)]),
               np.r_[areas, remainder + 1, 0, 0, 0])]
    _, results = check_passes(fs, passes, seed=4, p_valid=0.9)
    assert [(t, c["area_sum"]) for t, c, _ in results] == [(top, 0), (top, 1), (top, 1)]


@pytest.mark.parametrize("preset", PRESETS)
def test_latency_and_idle(preset):
    """Back to back: the sum is complete and ``idle`` high exactly ``latency`` edges after the last
    transfer (the documented 14); a clear starts from zero."""
    fs = FormatSet.preset(preset)
    rng = np.random.default_rng(5)
    passes = [random_triangles(fs, 40, rng, spread=4), random_triangles(fs, 1, rng, spread=4)]
    dut, results = check_passes(fs, passes)
    assert dut.latency == AreaError.latency_of(fs) == 14
    assert [edges for *_, edges in results] == [dut.latency, dut.latency]


def test_parameter_validation():
    # A component whose __init__ raises is still reported as unused when collected.
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UnusedElaboratable)
        with pytest.raises(TypeError, match="AreaError needs a FormatSet or a preset name, not 3"):
            AreaError(3)
        gc.collect()


@pytest.mark.parametrize("preset", PRESETS)
def test_converts_to_verilog(preset, monkeypatch):
    """Top level: the constant ``i.ready`` is left out of the ports (amaranth-lang/amaranth#1574)."""
    monkeypatch.setenv("AMARANTH_USE_YOSYS", "builtin")
    fs = FormatSet.preset(preset)
    text = top_level_verilog(AreaError(fs), "area_error")
    assert "module area_error" in text
    assert f"output [{fs.error_acc.width - 1}:0] total;" in text
