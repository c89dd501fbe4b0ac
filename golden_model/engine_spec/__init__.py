"""The engine's specification: what the RTL, the host driver and the exports all read.

The memory images, their word layouts and the engine's capacity (:mod:`.image`), the register
map on the Wishbone bus (:mod:`.register_map`) and the UART host link's frame format
(:mod:`.uart_protocol`).  The arithmetic they carry is :mod:`golden_model.fixed`'s; see
``docs/engine.md`` and ``docs/board.md``.
"""
