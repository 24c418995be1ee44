"""The optimiser loop every fit shares (Levenberg–Marquardt) and the SPD parametrisation of stiffness."""

from .jackknife import group_jackknife_covariance as group_jackknife_covariance
from .least_squares import LeastSquaresResult as LeastSquaresResult
from .least_squares import covariance as covariance
from .least_squares import least_squares as least_squares
from .spd import damping_start as damping_start
from .spd import lm_iterations as lm_iterations
from .spd import log_stiffness as log_stiffness
from .spd import params_from_stiffness as params_from_stiffness
from .spd import params_from_stiffness_jax as params_from_stiffness_jax
from .spd import params_vector as params_vector
from .spd import spd_size as spd_size
from .spd import stiffness_from_params as stiffness_from_params
from .spd import stiffness_matrix as stiffness_matrix
from .spd import sym_index as sym_index
