"""Fits of the λ0-PMP through the reaches of continuous joint-angle recordings, on any chain."""

from .fit import MovementFit as MovementFit
from .fit import fit_movements as fit_movements
from .plots import plot_movement_parameters as plot_movement_parameters
from .plots import plot_movements as plot_movements
from .predict import BASELINES as BASELINES
from .predict import MovementPrediction as MovementPrediction
from .predict import predict_movements as predict_movements
