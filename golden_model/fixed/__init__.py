"""Fixed-point foundation of the bit-accurate golden model.

Formats and quantisation primitives (:mod:`.format`), the pipeline's format set
(:mod:`.formats_set`), the rsqrt unit model (:mod:`.rsqrt`) and the exp-LUT step
generator (:mod:`.steplut`).  See ``docs/fixed-point-units.md``.
The engine's memory images, register map and bus words are :mod:`golden_model.engine_spec`.
"""

from .format import (
    MAX_PRODUCT_WIDTH,
    MAX_WIDTH,
    Format,
    Overflow,
    Rounding,
    SaturationCounter,
    add,
    apply_overflow,
    as_raw,
    mul,
    quantize,
    requantize,
    shift_round,
    sub,
    to_float,
)
from .formats_set import CONTROLLER_FIELDS, FORMAT_FIELDS, PRESET_DIR, UNITS, FormatSet, Product
from .rsqrt import (
    RSQRT_GUARD_BITS,
    RsqrtConfig,
    bit_length,
    measure_rsqrt,
    rsqrt_exact,
    rsqrt_seed_table,
    rsqrt_stages,
    rsqrt_with_config,
)
from .steplut import (
    DT_MAX,
    DT_MIN,
    LUT_RATE,
    LUT_SCALE,
    dt_constant,
    exp_lut,
    exp_table,
    lut_slope_bits,
    lut_value_float,
    measure_step_size,
    half_dt_sq,
    step_size,
    step_size_error_bound,
    step_size_float,
)

__all__ = [
    "MAX_PRODUCT_WIDTH", "MAX_WIDTH", "Format", "Overflow", "Rounding", "SaturationCounter",
    "add", "apply_overflow", "as_raw", "mul", "quantize", "requantize", "shift_round", "sub",
    "to_float",
    "CONTROLLER_FIELDS", "FORMAT_FIELDS", "PRESET_DIR", "UNITS", "FormatSet", "Product",
    "RSQRT_GUARD_BITS", "RsqrtConfig", "bit_length", "measure_rsqrt", "rsqrt_exact",
    "rsqrt_seed_table", "rsqrt_stages", "rsqrt_with_config",
    "DT_MAX", "DT_MIN", "LUT_RATE", "LUT_SCALE", "dt_constant", "exp_lut", "exp_table",
    "lut_slope_bits", "lut_value_float", "measure_step_size", "step_size", "half_dt_sq", "step_size_error_bound", "step_size_float",
]
