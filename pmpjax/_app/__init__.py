"""The application around the science: the command line (``cli``), the main job (``reproduce``,
its ``parts`` protocol, ``workers`` and ``display``), its ``report``, the ``simulate`` subcommand
and pmpjax's own parts (``figures``, ``primitives``). Nothing in the science modules imports it,
except the public face's ``read_simulation_config``."""
