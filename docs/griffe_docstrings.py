"""Griffe extension for the API reference: docstrings written for both `help()` and the site.

pmpjax's docstrings are Markdown with bold section titles (``**Arguments:**``, ``**Returns:**``,
``**Raises:**``) and a few Sphinx roles (``:func:`simulate```). Two rewrites make them render:

- a role becomes a cross-reference when it names a public name of ``pmpjax`` or ``fitting``
  (``[`simulate`][pmpjax.simulate]``), and inline code otherwise;
- a list that follows a paragraph line directly (``**Arguments:**`` then ``- ``q``: ...``) gets the
  blank line Markdown needs to see a list;

and a method that overrides a documented one without a docstring of its own shows the inherited one.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import griffe

ROOT = Path(__file__).resolve().parents[1]
ROLE = re.compile(r":(?:class|func|data|meth|attr|mod|obj|exc):`~?([^`]+)`")


def public_names() -> dict[str, set[str]]:
    """{package: names} from the ``X as X`` re-exports of each package's ``__init__.py``."""
    out = {}
    for pkg in ("pmpjax", "fitting"):
        tree = ast.parse((ROOT / pkg / "__init__.py").read_text())
        out[pkg] = {a.asname or a.name for n in tree.body if isinstance(n, ast.ImportFrom) for a in n.names}
    return out


PUBLIC = public_names()


def _role(match: re.Match, home: str) -> str:
    target = match.group(1).strip()
    parts = target.split(".")
    name = parts[-1]
    if parts[0] in PUBLIC and len(parts) == 2 and name in PUBLIC[parts[0]]:
        return f"[`{name}`][{parts[0]}.{name}]"
    if len(parts) == 1:
        for pkg in (home, *(p for p in PUBLIC if p != home)):
            if name in PUBLIC.get(pkg, ()):
                return f"[`{name}`][{pkg}.{name}]"
    return f"`{target}`"


def _lists(text: str) -> str:
    lines = text.split("\n")
    out = []
    for line in lines:
        prev = out[-1] if out else ""
        if line.startswith(("- ", "* ")) and prev.strip() and not prev.startswith(("- ", "* ", " ")):
            out.append("")
        out.append(line)
    return "\n".join(out)


def rewrite(text: str, home: str) -> str:
    return _lists(ROLE.sub(lambda m: _role(m, home), text))


def _classes(obj):
    """Every class defined in a module tree (aliases, i.e. re-exports, left out)."""
    for member in obj.members.values():
        if member.is_alias:
            continue
        if member.is_class:
            yield member
            yield from _classes(member)
        elif member.is_module:
            yield from _classes(member)


class Docstrings(griffe.Extension):
    """Rewrite Sphinx roles and list spacing in every docstring of pmpjax and fitting, and give a
    method that overrides a documented one without a docstring of its own the inherited one (as
    ``inspect.getdoc`` and ``help()`` do)."""

    def on_package(self, *, pkg, **kwargs) -> None:
        if pkg.name not in PUBLIC:
            return
        for cls in _classes(pkg):
            try:
                mro = cls.mro()
            except Exception:  # a base outside the loaded packages: nothing to inherit from here
                continue
            for name, member in cls.members.items():
                if member.is_alias or not member.is_function or member.docstring is not None:
                    continue
                for base in mro:
                    inherited = base.members.get(name)
                    if inherited is not None and not inherited.is_alias and inherited.docstring is not None:
                        member.docstring = griffe.Docstring(inherited.docstring.value, parent=member)
                        break

    def on_instance(self, *, node, obj, agent, **kwargs) -> None:
        doc = obj.docstring
        if doc is None:
            return
        home = obj.path.split(".")[0]
        if home in PUBLIC:
            doc.value = rewrite(doc.value, home)
