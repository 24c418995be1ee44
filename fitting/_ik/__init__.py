"""IK weights (Khoramshahi et al. 2022): Algorithm 1 and its LM variant, the analysis of estimated
weights, data sets, the paper's examples, figures and data files."""

from .analysis import BootstrapResult as BootstrapResult
from .analysis import HotellingResult as HotellingResult
from .analysis import bootstrap_ik_weights as bootstrap_ik_weights
from .analysis import contribution_coefficients as contribution_coefficients
from .analysis import hotelling_t2 as hotelling_t2
from .analysis import ik_decomposition as ik_decomposition
from .analysis import overspecified_joints as overspecified_joints
from .datasets import hugmp_ik_weights as hugmp_ik_weights
from .datasets import prosthetic_simulation as prosthetic_simulation
from .datasets import synthetic_ik_dataset as synthetic_ik_dataset
from .examples import ik_fig1_data as ik_fig1_data
from .examples import ik_fig3_data as ik_fig3_data
from .files import read_ik_file as read_ik_file
from .plots import plot_ik_weights as plot_ik_weights
from .weights import IKWeightsLMResult as IKWeightsLMResult
from .weights import IKWeightsResult as IKWeightsResult
from .weights import estimate_ik_weights as estimate_ik_weights
from .weights import estimate_ik_weights_lm as estimate_ik_weights_lm
from .weights import ik_model_error as ik_model_error
