"""Subject parameters of Tommasino & Campolo (2017), Tables 1–2, shipped as package data.

``KJ`` is rebuilt symmetric from the six printed entries (K11 K12 K13 K22 K23 K33; 1 = PS,
2 = FE, 3 = RUD). The printed traces are 3.99–4.00 because of two-decimal rounding; by default
``KJ`` is rescaled to trace exactly 4 Nm/rad (a change of at most 0.25 %, which leaves the
eigenvalue ratios — all that shapes Donders' law — untouched and matches the NIO fit's
parameterisation). ``normalize=False`` returns the table as printed.
"""

from __future__ import annotations

import dataclasses
import json
from functools import cache
from importlib import resources

import numpy as np

_FILE = "tommasino2017_tables.json"


@dataclasses.dataclass(frozen=True)
class Subject:
    """One subject of Tommasino & Campolo (2017), Tables 1–2 (made by :func:`load_subject`).

    **Fields:**

    - ``name``: ``"subj1"`` … ``"subj6"``.
    - ``KJ``: (3, 3) SPD joint stiffness [Nm/rad].
    - ``q_rest``: (3,) rest posture ``(q_PS, q_FE, q_RUD)`` [rad].
    """

    name: str
    KJ: np.ndarray
    q_rest: np.ndarray


@cache
def _table() -> dict:
    return json.loads(resources.files("pmpjax").joinpath("data", _FILE).read_text())


def subject_names() -> tuple[str, ...]:
    """Names of the tabulated subjects.

    **Returns:**

    ``("subj1", ..., "subj6")``.
    """
    return tuple(_table()["subjects"])


def load_subject(name: str, *, normalize: bool = True) -> Subject:
    """One subject of Tables 1–2 by name.

    **Arguments:**

    - ``name``: ``"subj1"`` … ``"subj6"`` (``"Subj 1"`` and ``1`` also work).
    - ``normalize``: rescale ``KJ`` to trace exactly 4 Nm/rad (the printed traces are 3.99–4.00);
      ``False`` gives the table as printed.

    **Returns:**

    The :class:`Subject`.

    **Raises:**

    - ``TypeError`` for a non-bool ``normalize``; ``ValueError`` for an unknown subject (naming the
      available ones).
    """
    if not isinstance(normalize, bool | np.bool_):
        raise TypeError(f"`normalize` must be a bool, got {type(normalize).__name__}")
    key = str(name).lower().replace(" ", "")
    if key.isdigit():
        key = f"subj{key}"
    subjects = _table()["subjects"]
    if key not in subjects:
        raise ValueError(f"unknown subject {name!r}; available: {', '.join(subjects)}")
    k11, k12, k13, k22, k23, k33 = subjects[key]["KJ"]
    KJ = np.array([[k11, k12, k13], [k12, k22, k23], [k13, k23, k33]], dtype=float)
    if normalize:
        KJ = KJ * (4.0 / np.trace(KJ))
    return Subject(key, KJ, np.array(subjects[key]["q_rest"], dtype=float))


def paper_subjects(*, normalize: bool = True) -> tuple[list[str], np.ndarray, np.ndarray]:
    """All six subjects of Tables 1–2, stacked.

    **Arguments:**

    - ``normalize``: rescale ``KJ`` to trace exactly 4 Nm/rad (the printed traces are 3.99–4.00);
      ``False`` gives the table as printed.

    **Returns:**

    ``(names, KJ, q_rest)``: six names, (6, 3, 3) stiffnesses [Nm/rad] and (6, 3) rest postures [rad].

    **Raises:**

    - ``TypeError`` for a non-bool ``normalize``.
    """
    if not isinstance(normalize, bool | np.bool_):
        raise TypeError(f"`normalize` must be a bool, got {type(normalize).__name__}")
    subs = [load_subject(n, normalize=normalize) for n in subject_names()]
    return [s.name for s in subs], np.stack([s.KJ for s in subs]), np.stack([s.q_rest for s in subs])
