"""Keywords renamed before 1.0: the old name keeps working for one release, with a warning."""

from __future__ import annotations

import functools
import warnings


def renamed_keywords(**renames: str):
    """Decorator for a function whose keywords ``old`` were renamed ``new`` (``old="new"``).

    A call with ``old=`` passes the value on as ``new=`` and emits a ``DeprecationWarning`` naming
    both; a call with both raises ``TypeError``. The wrapped function keeps its signature (with the
    new names) for ``inspect.signature`` and the documentation.
    """

    def wrap(fn):
        @functools.wraps(fn)
        def call(*args, **kwargs):
            for old, new in renames.items():
                if old in kwargs:
                    if new in kwargs:
                        raise TypeError(f"{fn.__name__}() got `{old}` and `{new}`; `{old}` is the old name of "
                                        f"`{new}`: pass `{new}` only")
                    warnings.warn(f"{fn.__name__}(): the keyword `{old}` is deprecated and will be removed in the "
                                  f"next release; use `{new}`", DeprecationWarning, stacklevel=2)
                    kwargs[new] = kwargs.pop(old)
            return fn(*args, **kwargs)

        return call

    return wrap
