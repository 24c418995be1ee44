"""The springy Cog-like arm (Williamson 1996): the MuJoCo arm, postural primitives, reflexes, figures.

This face holds what other families use; they import the family through it only."""

from .arm import load_arm as load_arm
from .arm import rollout as rollout
from .plots import plot_force_field as plot_force_field
from .plots import plot_reflex as plot_reflex
from .plots import plot_summed_moves as plot_summed_moves
from .primitives import PRIMITIVE_NAMES as PRIMITIVE_NAMES
from .primitives import arm_equilibrium as arm_equilibrium
from .primitives import blend as blend
from .primitives import default_primitives as default_primitives
from .primitives import moves_from_targets as moves_from_targets
from .primitives import summed_moves as summed_moves
from .primitives import winner_take_all as winner_take_all
from .reflexes import reflex_network as reflex_network
from .reflexes import run_reflexes as run_reflexes
from .reflexes import script_inputs as script_inputs
from .reflexes import stack_inputs as stack_inputs
