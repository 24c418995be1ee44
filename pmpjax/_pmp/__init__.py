"""The λ0-PMP: redundancy operators, PMP models, planners, the integrator, simulate, equilibria.

This face holds what other families use; they import the family through it only."""

from .equilibria import equilibrium_posture as equilibrium_posture
from .models import PMP1 as PMP1
from .models import PMP2 as PMP2
from .models import Lambda0PMP as Lambda0PMP
from .models import damping_from_stiffness as damping_from_stiffness
from .planners import ArimotoPlanner as ArimotoPlanner
from .planners import ConstantPlanner as ConstantPlanner
from .planners import MinimumJerkPlanner as MinimumJerkPlanner
from .redundancy import weighted_pinv as weighted_pinv
from .simulate import SaveAt as SaveAt
from .simulate import simulate as simulate
from .simulate import simulate_sequence as simulate_sequence
