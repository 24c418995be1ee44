"""fitting: batched, differentiable parameter fits built on pmpjax (never imported by pmpjax)."""

from ._optimise import LeastSquaresResult as LeastSquaresResult
from ._optimise import covariance as covariance
from ._optimise import least_squares as least_squares
from ._donders import DondersFit as DondersFit
from ._donders import fit_donders as fit_donders
from ._donders import parameter_names as parameter_names
from ._donders import params_from_stiffness as params_from_stiffness
from ._donders import predicted_torsion as predicted_torsion
from ._donders import stiffness_from_params as stiffness_from_params
