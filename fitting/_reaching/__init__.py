"""Real human reaching (HuG-MP): fit the λ0-PMP per subject, predict held-out movements, baselines.

``motions`` turns recordings into tasks, ``model`` holds the λ0-PMP on normalised time and its
residuals, ``fit`` the per-subject fit, ``predict`` the held-out predictions and baselines,
``plots`` the figure. The private names below serve benchmarks/reaching.py.
"""

from .fit import ReachingFit as ReachingFit
from .fit import _fit_motions as _fit_motions
from .fit import fit_reaching as fit_reaching
from .model import DAMPINGS as DAMPINGS
from .model import MODELS as MODELS
from .model import TIME_CONSTANTS as TIME_CONSTANTS
from .model import _Config as _Config
from .motions import SAMPLES as SAMPLES
from .motions import _motions as _motions
from .plots import plot_reaching_subject as plot_reaching_subject
from .predict import BASELINES as BASELINES
from .predict import ReachingPrediction as ReachingPrediction
from .predict import predict_reaching as predict_reaching
