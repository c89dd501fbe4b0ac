"""The Verilog module names of the handoff's tops, in one place (no Amaranth import, so the CLI
and the synthesis driver can name them before anything is elaborated)."""

#: The per-node datapath with its step generator (``hdl.SpringflatCore``).
CORE_MODULE = "springflat_core"

#: The whole flattener behind its Wishbone bus (``hdl.SpringflatEngine``).
ENGINE_MODULE = "springflat_engine"

#: The simulation top around the engine (``sim.engine_run.simulation_harness``).
ENGINE_SIM_MODULE = "springflat_engine_sim"

#: The handoff's components other than the engine, each a Verilog module of its own: name → what it is
#: (``sim.export.COMPONENTS`` builds them; ``springflat synth --components`` names them).
COMPONENT_SUMMARIES = {
    "rsqrt_unit": "reciprocal square root, |Δ|² → r",
    "step_generator": "exp-LUT step generator, (E_S, E_C) → (Δt, ½Δt²)",
    "node_update": "node-update datapath: neighbour entries → updated nodes",
    CORE_MODULE: "top: node-update datapath + step generator + step registers",
    "guard_certificate": "the step guard's inversion test: a triangle's corners and proposed moves → its level "
                         "(docs/engine-guard.md; in the engine at II 2)",
    "guard_certificate_ii2": "the same at an initiation interval of 2: half the multipliers",
}
