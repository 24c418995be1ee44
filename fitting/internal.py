"""The internal surface of ``fitting``: the kernels, constants and per-item steps behind its public
fits, for benchmarks and packages built on fitting. Like ``pmpjax.internal``: documented and
tested, but not part of the stable API — names here may change between releases without
deprecation. Nothing here belongs to the application (``fitting._app``).
"""

# Donders (NIO): the batched fit kernel, its residual and the starting points of its restarts
from ._donders.fit import fit_nio_batch as fit_nio_batch
from ._donders.fit import nio_residual as nio_residual
from ._donders.fit import nio_starts as nio_starts

# The movement fit's module, whose stage functions and step limits the movements benchmark wraps
# within its own process to time each stage
from ._movements import fit as movement_fit_module

# Wrist pointing: the smoothing spline's discrete kernel (Silverman 1984) behind the model's
# observation; the time-constant fit's normalised-time grid and per-item data
from ._pointing.observe import _silverman_weights as silverman_weights
from ._pointing.time_constants import FIT_DT as FIT_DT
from ._pointing.time_constants import FIT_SPAN as FIT_SPAN
from ._pointing.time_constants import _item_data as time_constant_item_data

# Reaching (HuG-MP): the model variants, samples per motion, the baselines, one subject's motions,
# the fit's configuration and the batched fit of motions behind ``fitting.fit_reaching``
from ._reaching.fit import _fit_motions as fit_reaching_motions
from ._reaching.model import DAMPINGS as REACHING_DAMPINGS
from ._reaching.model import MODELS as REACHING_MODELS
from ._reaching.model import TIME_CONSTANTS as REACHING_TIME_CONSTANTS
from ._reaching.model import _Config as ReachingConfig
from ._reaching.model import _param_names as reaching_param_names
from ._reaching.motions import SAMPLES as REACHING_SAMPLES
from ._reaching.motions import _Motions as ReachingMotions
from ._reaching.motions import _motions as reaching_motions
from ._reaching.predict import BASELINES as REACHING_BASELINES

# Sweeps: the local engine (one compiled kernel over the local devices), the store's atomic chunk
# write, the example kernels (a curvature-map row; a Donders power-analysis row: data generation
# and the NIO fit)
from ._sweep.engines import _LocalEngine as LocalEngine
from ._sweep.examples import curvature_row as curvature_row
from ._sweep.examples import donders_power_row as donders_power_row
from ._sweep.store import _atomic_write as atomic_write

__all__ = [
    "FIT_DT", "FIT_SPAN", "REACHING_BASELINES", "REACHING_DAMPINGS", "REACHING_MODELS",
    "REACHING_SAMPLES", "REACHING_TIME_CONSTANTS", "atomic_write", "curvature_row",
    "donders_power_row", "fit_nio_batch", "fit_reaching_motions", "LocalEngine",
    "movement_fit_module", "nio_residual", "nio_starts", "reaching_motions", "ReachingConfig", "ReachingMotions",
    "reaching_param_names",
    "silverman_weights", "time_constant_item_data",
]
