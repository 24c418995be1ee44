"""Fits of the λ0-PMP through the reaches of continuous joint-angle recordings, on any chain."""

# Public (fitting's face): MovementFit, fit_movements, the plots, predict_movements, MovementPrediction,
# BASELINES. The others are the engine behind fit_movements, for its HuG-MP case (fitting._reaching).
from .data import SubjectReaches as SubjectReaches
from .fit import MovementFit as MovementFit
from .fit import _fit as fit_subjects  # noqa: F401
from .fit import _reach_jackknife_covariance as reach_jackknife_covariance  # noqa: F401
from .fit import fit_movements as fit_movements
from .model import BOUND_WIDTH as BOUND_WIDTH
from .model import GAIN_CAP as GAIN_CAP
from .model import Config as ReachModelConfig  # noqa: F401
from .model import bound_residual as bound_residual
from .model import free_index as free_index
from .model import n_params as n_params
from .model import rk4_rates as rk4_rates
from .model import simulate as simulate_samples  # noqa: F401
from .model import stage2_start as stage2_start
from .model import unpack as unpack_params  # noqa: F401
from .plots import plot_movement_parameters as plot_movement_parameters
from .plots import plot_movements as plot_movements
from .predict import BASELINES as BASELINES
from .predict import MovementPrediction as MovementPrediction
from .predict import predict_movements as predict_movements
