"""The suite's own scheduling (``tests/conftest.py``): the files handed out first exist."""

from pathlib import Path

import conftest


def test_slowest_first_names_existing_test_files_once():
    """A renamed or split long file would silently drop to the end of the queue and run alone
    there, after the other worker has finished."""
    names = conftest.SLOWEST_FIRST
    missing = [n for n in names if not (Path(__file__).parent / n).is_file()]
    assert not missing, f"conftest.SLOWEST_FIRST names files that do not exist: {missing}"
    assert len(set(names)) == len(names)
