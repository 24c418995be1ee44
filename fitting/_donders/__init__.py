"""Donders' law: the NIO fit of stiffness and rest posture, its coefficients and torsion."""

from .._optimise import log_stiffness as log_stiffness
from .._optimise import params_from_stiffness as params_from_stiffness
from .._optimise import stiffness_from_params as stiffness_from_params
from .coefficients import coefficient_names as coefficient_names
from .coefficients import donders_coefficients as donders_coefficients
from .coefficients import parameter_names as parameter_names
from .coefficients import predicted_torsion as predicted_torsion
from .fit import DondersFit as DondersFit
from .fit import fit_average_donders as fit_average_donders
from .fit import fit_donders as fit_donders
from .fit import fit_nio_batch as fit_nio_batch
from .fit import nio_residual as nio_residual
from .fit import nio_starts as nio_starts
