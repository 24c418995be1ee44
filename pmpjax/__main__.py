"""``python -m pmpjax``: the command line (``pmpjax._app.cli``)."""

import sys

import pmpjax

if getattr(pmpjax, "__file__", None) is None:
    # Run in the folder that holds a clone named pmpjax, Python imports the clone's folder (no code
    # of its own) instead of the installed package, and nothing works.
    print(f"pmpjax: Python imported the folder {', '.join(pmpjax.__path__)} instead of the installed pmpjax "
          "(python -m puts the current folder first). Run the command from any other folder, or use the "
          "`pmpjax` command, which works from anywhere", file=sys.stderr)
    sys.exit(2)

from ._app.cli import main  # noqa: E402

sys.exit(main())
