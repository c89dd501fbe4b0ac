"""``springflat study``: the flow of fixed-point error studies and word-length optimisation.

The model part (a case, knobs, comparison records) is :mod:`golden_model.study`; here are the cases
built from mesh names with their start layouts (:mod:`.cases`), the RTL cost model (:mod:`.cost`), the runs
over a process pool or a caller's executor with the greedy optimiser (:mod:`.flow`) and the command with its
files and plots (:mod:`.cli`).

**Cost model** (:func:`~.cost.cost`): ``total_bits`` = sum of the widths of the node
datapath formats (:data:`~golden_model.study.DATAPATH_FIELDS`: every format but the step
generator's ``error`` and ``lut_entry`` and the controller's); ``dsp`` = the 18×18 DSP
blocks of the RTL (:func:`~.cost.multipliers`): every multiplication of ``fs.products()`` in the
node datapath, its rsqrt unit and the step generator, times its instances, split into
partial products by the rule the RTL uses (:mod:`golden_model.fixed.dsp`);
``rom_bits`` = rsqrt seed ROM + exp-LUT bits.  Costs compare
lexicographically: ``(total_bits, dsp, rom_bits)`` for the ``bits`` metric,
``(dsp, total_bits, rom_bits)`` for ``dsp``.

**Optimiser** (:meth:`~.flow.Study.optimise`): greedy word-length reduction from a
base set that meets the :class:`~golden_model.study.AccuracyTarget`: each round lists the
cost-reducing moves (1, 2, 4 or 8 fraction bits less in a signal class, one
LUT index or seed bit less, one Newton step less, interpolation off), tries
them from the largest cost reduction down (ties: the least sensitive knob in
the sweep first) and keeps the first one with which every case still meets
the target — i.e. the acceptable move that reduces the cost most.  A move
that fails is not retried in later rounds until every remaining move has
failed; then every single-bit move is retried once against the current
configuration, so the result is a configuration from which no single move
is acceptable.  Moves to values the one-knob sweep already showed to miss the
target are skipped (``prune``).  Candidates are evaluated case by case (the
case most likely to fail first) and abandoned at the first failing case.
The float reference of each case is computed once and cached.

Runs are spread over worker processes (``workers``).
"""
