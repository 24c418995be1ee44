"""Kinematic chains: the chain protocol, the wrist (Eq 6), planar arms, user FK, MJCF sites, the HuG-MP
shoulder-elbow arm.

This face holds what other families use; they import the family through it only."""

from .kinematics import Chain as Chain
from .kinematics import PlanarArm as PlanarArm
from .kinematics import Wrist as Wrist
from .kinematics import manipulability_soa as manipulability_soa
from .mjcf import MjcfChain as MjcfChain
from .mjcf import gravity_from_kinematics as gravity_from_kinematics
from .mjcf import gravity_gradients as gravity_gradients
from .mjcf import gravity_terms as gravity_terms
from .mjcf import kinematics as kinematics
from .mjcf import site_position as site_position
