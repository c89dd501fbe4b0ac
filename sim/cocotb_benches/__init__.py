"""cocotb benches of the exported Verilog (run by :mod:`sim.cocotb_support`).

Each bench reads its configuration from the JSON file named by
``SPRINGFLAT_BENCH_CONFIG`` and writes its findings to ``SPRINGFLAT_BENCH_RESULT``.
Stimulus and expected values come from the golden model.
"""
