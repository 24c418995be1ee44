"""Wrist pointing (Tommasino & Campolo 2017): orientations, Donders surfaces and recordings, the
center-out protocol, curvature, pointing recordings, Figure 3, the paper's subjects.

This face holds what other families use; they import the family through it only."""

from .center_out import center_out_targets as center_out_targets
from .figure3 import figure3_data as figure3_data
from .figure3 import plot_figure3 as plot_figure3
