"""``import fitting`` first checks that ``pmpjax`` is the installed package.

A script run from, or ``python -m`` in, the folder that holds a clone named ``pmpjax`` puts that
folder first on ``sys.path``, and Python imports the clone's folder (no code of its own) as an
empty namespace package instead of the installed pmpjax; fitting then failed with "cannot import
name 'Status' from 'pmpjax' (unknown location)". This says what happened instead.
"""

import pmpjax

if getattr(pmpjax, "__file__", None) is None:
    raise ImportError(
        f"Python imported the folder {', '.join(pmpjax.__path__)} instead of the installed pmpjax (a script "
        "or python -m run in the folder that holds a clone named pmpjax puts that folder first): run it from "
        "any other folder")
