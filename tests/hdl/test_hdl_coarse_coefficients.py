"""RTL coarse coefficients (hdl.CoarseCoefficients) against the golden model's coefficients and move_shift of
move_frac_bits, in Amaranth's simulator: every coefficient's mantissa and the move's shift, bit for bit, with the
matrix read from a stand-in block RAM (a registered read) and random valid/ready stalls."""

import numpy as np
import pytest

from golden_model.coarse import basis_exponents
from golden_model.fixed import FormatSet
from golden_model.fixed.coarse import (MATRIX_BITS, SUM_BITS, CoarseConstants, coefficients, move_frac_bits,
                                       move_shift, sum_bits)
from hdl.coarse_coefficients import CoarseCoefficients
from sim.payloads import pack, unpack_beats
from support import PRESETS
from support.streams import StreamRun, run_testbenches, stream_consumer, stream_producer

MAX_NODES = 2048


def random_case(rng, m, scale_bits):
    """A matrix of 25-bit entries (one at an end of their range) and sums of about ``scale_bits`` bits."""
    limit = (1 << MATRIX_BITS) - 1
    matrix = rng.integers(-limit, limit + 1, size=(m, m))
    matrix[rng.integers(m), rng.integers(m)] = limit * rng.choice([-1, 1])
    top = (1 << (sum_bits(MAX_NODES) - 1)) - 1
    limit = min(top, 1 << scale_bits)
    sums = rng.integers(-limit, limit + 1, size=(m, 2))
    return matrix, sums


def run_cases(fs, degree, cases, exponent, *, seed=0, p_valid=1.0, p_ready=1.0, read_latency=1):
    """Each ``(matrix, sums)`` through the RTL (one matrix memory per case, swapped when a case is taken):
    the outputs as ``(coefficients (m, 2), move_shift)``. The stand-in memory answers ``read_latency`` clocks
    after the address."""
    m = len(basis_exponents(degree))
    dut = CoarseCoefficients(fs, degree, MAX_NODES, read_latency=read_latency)
    beats = [pack(dut.i.payload.shape(), {"sums": {k: {"x": int(s[k, 0]), "y": int(s[k, 1])} for k in range(m)}})
             for _, s in cases]
    run = StreamRun()

    async def memory(ctx):  # registered reads: the entry at the address of one clock, read_latency clocks later
        ctx.set(dut.matrix_exponent, exponent)
        addresses = [0] * read_latency
        async for _, _, addr in ctx.tick().sample(dut.matrix_addr):
            if len(run.outputs) == len(cases):  # (the simulation ends when every testbench has returned)
                return
            addresses = [*addresses[1:], addr]
            ctx.set(dut.matrix_data, int(cases[max(len(run.in_cycles) - 1, 0)][0].ravel()[addresses[0]]))

    run_testbenches(dut, memory,
                    stream_producer(dut.i, beats, run, seed=seed, p_valid=p_valid),
                    stream_consumer(dut.o, len(cases), run, seed=seed + 1, p_ready=p_ready, drain=10,
                                    max_cycles=len(cases) * (dut.cycles + 50) * 4 + 200, probe_ready=True))
    out = unpack_beats(dut.o.payload.shape(), run.outputs)
    return [(np.array([[out["coefficients"][k]["x"][i], out["coefficients"][k]["y"][i]] for k in range(m)]),
             int(out["move_shift"][i])) for i in range(len(cases))], run, dut


@pytest.mark.parametrize("preset", PRESETS)
@pytest.mark.parametrize("degree", [1, 3])
def test_coefficients_and_the_move_shift_bit_for_bit(preset, degree):
    fs = FormatSet.preset(preset)
    rng = np.random.default_rng(degree)
    m = len(basis_exponents(degree))
    cases = [random_case(rng, m, bits) for bits in (0, 5, 20, 23, 30, sum_bits(MAX_NODES) - 1)]
    cases.append((cases[0][0], np.zeros((m, 2), dtype=np.int64)))  # no forces: every exponent 0
    # the largest a negative power of two, counted by its leading sign bits (-2^k has k bits, 2^k k + 1): in the
    # sums, and through an identity matrix in the products, where it moves c's exponent and mantissas
    edge = np.full((m, 2), 12345, dtype=np.int64)
    edge[0, 0] = -(1 << (SUM_BITS - 2))
    cases.append((cases[0][0], edge))
    edge = np.full((m, 2), 3, dtype=np.int64)
    edge[0, 0] = -(1 << 20)
    cases.append((np.eye(m, dtype=np.int64), edge))
    exponent = 30
    results, _, _ = run_cases(fs, degree, cases, exponent, p_valid=0.6, p_ready=0.5, seed=degree)
    for (matrix, sums), (c, shift) in zip(cases, results):
        constants = CoarseConstants(np.zeros((1, m), dtype=np.int64), matrix, exponent)
        want, sum_exponent, c_exponent = coefficients(constants, sums)
        assert np.array_equal(c, want), (sums.tolist(), c.tolist(), want.tolist())
        assert shift == move_shift(fs, move_frac_bits(fs, constants, sum_exponent, c_exponent))


@pytest.mark.parametrize("exponent", [-100, 0, 60, 127])
def test_the_move_shift_is_clamped_at_both_ends_of_its_range(exponent):
    fs = FormatSet.preset("default")
    rng = np.random.default_rng(9)
    case = random_case(rng, 3, 20)
    (c, shift), = run_cases(fs, 1, [case], exponent)[0]
    constants = CoarseConstants(np.zeros((1, 3), dtype=np.int64), case[0], exponent)
    _, sum_exponent, c_exponent = coefficients(constants, case[1])
    assert shift == move_shift(fs, move_frac_bits(fs, constants, sum_exponent, c_exponent))


def test_the_cycles_of_the_contract():
    fs = FormatSet.preset("default")
    rng = np.random.default_rng(3)
    cases = [random_case(rng, 10, 20) for _ in range(2)]
    _, run, dut = run_cases(fs, 3, cases, 20)
    assert dut.cycles == 2793  # the contract's count at degree 3, pinned (docs/hardware-units.md)
    assert [o - i for i, o in zip(run.in_cycles, run.out_cycles)] == [dut.cycles] * 2


@pytest.mark.parametrize("read_latency", [2, 3])
def test_a_slower_matrix_read_gives_the_same_results_a_clock_more_per_product(read_latency):
    """``read_latency``: the matrix memory answers later (the engine's memories register the address), each of
    the ``m²`` reads waits for it; the results are the same bit for bit."""
    fs = FormatSet.preset("default")
    rng = np.random.default_rng(30 + read_latency)
    cases = [random_case(rng, 10, bits) for bits in (5, 30)]
    results, run, dut = run_cases(fs, 3, cases, 25, p_valid=0.7, p_ready=0.6, read_latency=read_latency)
    for (matrix, sums), (c, shift) in zip(cases, results):
        constants = CoarseConstants(np.zeros((1, 10), dtype=np.int64), matrix, 25)
        want, sum_exponent, c_exponent = coefficients(constants, sums)
        assert np.array_equal(c, want)
        assert shift == move_shift(fs, move_frac_bits(fs, constants, sum_exponent, c_exponent))
    assert dut.cycles == 2793 + 100 * (read_latency - 1)
    _, run, _ = run_cases(fs, 3, cases, 25, read_latency=read_latency)
    assert [o - i for i, o in zip(run.in_cycles, run.out_cycles)] == [dut.cycles] * 2
