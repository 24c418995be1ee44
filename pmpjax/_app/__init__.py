"""The application around the science: the command line (``cli``), the main job (``reproduce``,
its ``parts`` protocol, ``workers`` and ``display``), its ``report``, the ``simulate`` subcommand
and pmpjax's own parts (``figures``, ``primitives``). No library module imports it.

This face holds what other applications built on pmpjax (``fitting._app``) use: the part protocol,
the command line's text functions, and the simulation-config reader of the data layer that the sweep
command extends.
"""

from .._data import ConfigError as ConfigError
from .._data import build_simulation as build_simulation
from .._data import read_config as read_config
from .parts import Part as Part
from .parts import PartContext as PartContext
from .text import example_help as example_help
from .text import plain as plain
from .text import plural as plural
from .text import positive_int as positive_int
