"""Wrist pointing (Tommasino & Campolo 2017): the analysis of recordings, λ0-PMP predictions,
fitted time constants and the paper's figures."""

from .analysis import PointingAnalysis as PointingAnalysis
from .analysis import analyze_pointing as analyze_pointing
from .pipeline import PointingModels as PointingModels
from .pipeline import fit_pointing_models as fit_pointing_models
from .plots import plot_pointing_curvature as plot_pointing_curvature
from .plots import plot_pointing_joints as plot_pointing_joints
from .plots import plot_pointing_paths as plot_pointing_paths
from .plots import plot_pointing_speed as plot_pointing_speed
from .prediction import PointingPrediction as PointingPrediction
from .prediction import predict_pointing as predict_pointing
from .time_constants import PointingModelFit as PointingModelFit
from .time_constants import TimeConstantFit as TimeConstantFit
from .time_constants import fit_pointing_model as fit_pointing_model
from .time_constants import fit_time_constants as fit_time_constants
