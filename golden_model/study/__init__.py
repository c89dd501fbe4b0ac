"""Error studies of the fixed-point golden model: cases, knobs and comparison records.

A *study* runs the bit-exact fixed-point engine (:func:`~golden_model.fixed.engine.flatten_fixed`)
with many :class:`~golden_model.fixed.FormatSet` configurations over a set of
*cases* (mesh × initial layout × step mode, :class:`StudyCase`; built from mesh names by
:mod:`sim.study.cases`) and compares every run with the
float reference (:func:`~golden_model.reference.flatten`).

Per run (:class:`RunRecord`, :mod:`.records`): final ``E_S`` and ``E_C`` absolute deviation from
the float run, max and RMS vertex position error in mean-edge units, iteration
difference, status match, saturation events, or the reason the configuration
or the mesh was refused.

**Knobs** (:data:`KNOBS`, :mod:`.knobs`): the fraction bits of each *signal class*
(:data:`SIGNAL_CLASSES`; tied formats move together so that the design
invariants of the presets hold: ``position``/``delta``/``face_edge`` share fraction bits so
narrowing only saturates, ``force``/``force_acc`` so accumulation is exact,
``rest_length``/``error_acc``/``face_area`` so error sums are exact, ``dt``/``lut_entry`` so
``dt = C + T(E_S) + T(E_C)`` is an exact sum, ``error``/``reciprocal`` so the reciprocals
keep their guard bits), ``lut_index_bits``,
``lut_interpolate``, ``rsqrt_seed_bits``, ``rsqrt_newton_steps`` and
``rounding``.  :func:`sweep_configs` makes one-knob-at-a-time sweeps around a
base set; combinations that :class:`FormatSet` refuses are kept with the
``ValueError`` message.  Integer bits are never changed (their need depends on
the meshes, not on accuracy; saturation events show when they are short).

The flow that runs a study (the process pool, the RTL cost model, the greedy word-length
optimiser) is :mod:`sim.study`; this package is the model part only.
"""

from .cases import GENERATED_PARAMS, StudyCase
from .knobs import (
    DATAPATH_FIELDS,
    DEFAULT_BITS,
    DEFAULT_STRIDES,
    KNOBS,
    OTHER_KNOB_VALUES,
    SIGNAL_CLASSES,
    Config,
    class_changes,
    class_frac_bits,
    fs_key,
    make_config,
    parse_bits,
    parse_knobs,
    preset_configs,
    sweep_configs,
    unexercised_classes,
)
from .records import RESULT_COLUMNS, AccuracyTarget, FixedOutcome, RunRecord, compare, measure_clamps, run_fixed

__all__ = [
    "GENERATED_PARAMS", "SIGNAL_CLASSES", "DATAPATH_FIELDS", "KNOBS",
    "OTHER_KNOB_VALUES", "DEFAULT_BITS", "DEFAULT_STRIDES", "RESULT_COLUMNS",
    "StudyCase", "Config", "RunRecord", "AccuracyTarget", "FixedOutcome",
    "parse_bits", "parse_knobs", "make_config", "class_frac_bits",
    "class_changes", "sweep_configs", "preset_configs", "fs_key", "run_fixed", "compare", "measure_clamps",
    "unexercised_classes",
]
