"""The documentation site: it builds in strict mode, and its API reference lists every public name.

``mkdocs build --strict`` fails on any warning: a broken link or anchor between pages, a
cross-reference in a docstring that resolves to nothing, a page missing from the navigation, a
``:::`` entry that names nothing. The public names are compared with the ``:::`` entries of
``docs/api/`` here, so a new public name without an entry fails even where the site builds.
"""

import inspect
import os
import re
import subprocess
import sys
from pathlib import Path

import fitting
import pmpjax as pj

ROOT = Path(__file__).resolve().parents[1]
API = ROOT / "docs" / "api"


def public_names(mod) -> set[str]:
    """``mod.__all__`` if the package declares it, else its non-underscore, non-module names."""
    names = getattr(mod, "__all__", None)
    if names is None:
        names = [n for n in dir(mod) if not n.startswith("_") and not inspect.ismodule(getattr(mod, n))]
    return {f"{mod.__name__}.{n}" for n in names}


def documented_names() -> dict[str, list[str]]:
    """{``pkg.name``: [pages]} of every ``::: pkg.name`` directive under docs/api/."""
    out: dict[str, list[str]] = {}
    for page in sorted(API.rglob("*.md")):
        for name in re.findall(r"^:::\s*(\S+)", page.read_text(encoding="utf-8"), flags=re.M):
            out.setdefault(name, []).append(str(page.relative_to(ROOT)))
    return out


def test_api_reference_lists_every_public_name_once():
    public = public_names(pj) | public_names(fitting)
    documented = documented_names()
    missing = sorted(public - set(documented))
    assert not missing, f"public names without a `::: name` entry under docs/api/: {missing}"
    unknown = sorted(set(documented) - public)
    assert not unknown, f"`:::` entries under docs/api/ that are not public names: {unknown}"
    twice = {n: p for n, p in documented.items() if len(p) > 1}
    assert not twice, f"public names documented more than once: {twice}"


def test_site_builds_strict(tmp_path):
    """The whole site, as `mkdocs build --strict` builds it; then spot checks of what it rendered."""
    site = tmp_path / "site"
    env = {**os.environ, "NO_MKDOCS_2_WARNING": "1"}
    proc = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "-f", str(ROOT / "mkdocs.yml"),
                           "-d", str(site)], cwd=ROOT, env=env, capture_output=True, text=True, timeout=300)
    log = proc.stdout + proc.stderr
    assert proc.returncode == 0, f"mkdocs build --strict failed:\n{log[-6000:]}"
    warnings = [line for line in log.splitlines() if re.match(r"\s*(WARNING|ERROR)\b", line)]
    assert not warnings, "mkdocs warned:\n" + "\n".join(warnings)
    # Every `:::` entry rendered as a heading with its anchor, on the page that names it.
    for name, pages in documented_names().items():
        html = (site / Path(pages[0]).relative_to("docs").with_suffix("") / "index.html").read_text(encoding="utf-8")
        assert f'id="{name}"' in html, f"{name}: no rendered entry on {pages[0]}"
    # API entries show signatures and the docstrings' sections.
    sim = (site / "api" / "pmpjax" / "simulation" / "index.html").read_text(encoding="utf-8")
    assert "duration" in sim and "<strong>Compile time:</strong>" in sim
    # The notebooks are rendered from their stored outputs: figures included, nothing executed.
    for nb in sorted((ROOT / "notebooks").glob("*.ipynb")):
        html = (site / "notebooks" / nb.stem / "index.html").read_text(encoding="utf-8")
        assert "data:image/png;base64" in html, f"{nb.name}: no figure in its page"
    # The gallery's images are copied with the site.
    for png in (ROOT / "docs" / "gallery").glob("*.png"):
        assert (site / "gallery" / png.name).is_file()
