"""Fits on the springy arm (Williamson 1996): blend weights that place the hand, stiffness from sag."""

from .fit import BlendFit as BlendFit
from .fit import StiffnessFit as StiffnessFit
from .fit import fit_blend_weights as fit_blend_weights
from .fit import fit_stiffness as fit_stiffness
