"""Real human reaching (HuG-MP): fit the λ0-PMP per subject, predict held-out movements, baselines.

``motions`` turns recordings into tasks, ``model`` holds the λ0-PMP on normalised time and its
residuals, ``fit`` the per-subject fit, ``predict`` the held-out predictions and baselines,
``plots`` the figure.
"""

from .fit import ReachingFit as ReachingFit
from .fit import fit_reaching as fit_reaching
from .model import DAMPINGS as DAMPINGS
from .model import MODELS as MODELS
from .model import TIME_CONSTANTS as TIME_CONSTANTS
from .motions import SAMPLES as SAMPLES
from .plots import plot_reaching_subject as plot_reaching_subject
from .predict import BASELINES as BASELINES
from .predict import ReachingPrediction as ReachingPrediction
from .predict import predict_reaching as predict_reaching
