"""The Verilog module names of the handoff's tops, in one place (no Amaranth import, so the CLI
and the synthesis driver can name them before anything is elaborated)."""

#: The per-node datapath with its step generator (``hdl.SpringflatCore``).
CORE_MODULE = "springflat_core"

#: The whole flattener behind its Wishbone bus (``hdl.SpringflatEngine``).
ENGINE_MODULE = "springflat_engine"

#: The simulation top around the engine (``sim.engine_run.simulation_harness``).
ENGINE_SIM_MODULE = "springflat_engine_sim"
