"""Parameter sweeps at scale (``sweep``), their designs, on-disk store and engines, and the examples' kernels."""

from .designs import grid as grid
from .designs import latin_hypercube as latin_hypercube
from .designs import params_from_csv as params_from_csv
from .designs import sobol as sobol
from .examples import curvature_row as curvature_row
from .examples import donders_power_row as donders_power_row
from .examples import plot_curvature_map as plot_curvature_map
from .sweep import SweepResult as SweepResult
from .sweep import sweep as sweep
