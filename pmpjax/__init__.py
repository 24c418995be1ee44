"""pmpjax: differentiable JAX toolkit for human-like posture and movement of redundant chains."""

from ._kinematics import Chain as Chain
from ._kinematics import FunctionChain as FunctionChain
from ._kinematics import PlanarArm as PlanarArm
from ._kinematics import Wrist as Wrist
from ._kinematics import manipulability as manipulability
from ._models import PMP1 as PMP1
from ._models import PMP2 as PMP2
from ._models import Lambda0PMP as Lambda0PMP
from ._models import damping_from_stiffness as damping_from_stiffness
from ._models import normalize_trace as normalize_trace
from ._planners import ArimotoPlanner as ArimotoPlanner
from ._planners import ConstantPlanner as ConstantPlanner
from ._planners import MinimumJerkPlanner as MinimumJerkPlanner
from ._planners import Planner as Planner
from ._planners import eq10_gain as eq10_gain
from ._protocol import DIRECTIONS as DIRECTIONS
from ._protocol import center_out_targets as center_out_targets
from ._protocol import center_out_trials as center_out_trials
from ._redundancy import lambda0 as lambda0
from ._redundancy import nullspace_projector as nullspace_projector
from ._redundancy import task_damping as task_damping
from ._redundancy import weighted_pinv as weighted_pinv
from ._simulate import SaveAt as SaveAt
from ._simulate import Trajectory as Trajectory
from ._simulate import simulate as simulate
from ._simulate import simulate_sequence as simulate_sequence

__version__ = "0.1.0"
