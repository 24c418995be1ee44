"""The documentation site: it builds in strict mode, its API reference lists every public name, and
every public docstring has the sections the reference renders.

``mkdocs build --strict`` fails on any warning: a broken link or anchor between pages, a
cross-reference in a docstring that resolves to nothing, a page missing from the navigation, a
``:::`` entry that names nothing. The public names are compared with the ``:::`` entries of
``docs/api/`` here, so a new public name without an entry fails even where the site builds.

Docstrings use one form (diffrax's): bold section titles ``**Arguments:**``, ``**Returns:**``,
``**Raises:**``; a function's Arguments section names each of its parameters, a class's docstring
names each of its constructor fields.
"""

import ast
import enum
import inspect
import os
import re
import subprocess
import sys
import textwrap
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


SECTION = re.compile(r"\*\*([A-Z][A-Za-z ]*?)(?: \([^)]*\))?:\*\*")


def sections(doc: str) -> dict[str, str]:
    """{title: text} of a docstring's bold sections (``**Arguments:**`` up to the next title)."""
    marks = list(SECTION.finditer(doc))
    return {m.group(1): doc[m.end(): marks[i + 1].start() if i + 1 < len(marks) else len(doc)]
            for i, m in enumerate(marks)}


def named(name: str, text: str) -> bool:
    """``name`` appears in code quotes: ```name```, ```name[...]``` or ```name(...)```."""
    return re.search(rf"`{re.escape(name)}[`\[(]", text) is not None


def own_body(func) -> list[ast.AST]:
    """The nodes of a function's own body (nested functions, lambdas and classes left out)."""
    tree = ast.parse(textwrap.dedent(inspect.getsource(func)))
    out, stack = [], list(tree.body[0].body)
    while stack:
        node = stack.pop()
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef | ast.Lambda | ast.ClassDef):
            continue
        out.append(node)
        stack.extend(ast.iter_child_nodes(node))
    return out


def returns_value(nodes) -> bool:
    return any((isinstance(n, ast.Return) and n.value is not None
                and not (isinstance(n.value, ast.Constant) and n.value.value is None))
               or isinstance(n, ast.Yield | ast.YieldFrom) for n in nodes)


def _not_implemented(node: ast.Raise) -> bool:
    """``raise NotImplementedError`` of an abstract method (not an error a caller can provoke)."""
    exc = node.exc.func if isinstance(node.exc, ast.Call) else node.exc
    return isinstance(exc, ast.Name) and exc.id == "NotImplementedError"


def constructor_fields(cls) -> list[str]:
    """What a user passes to build one: the constructor's parameters (a dataclass's init fields)."""
    return [p for p in inspect.signature(cls).parameters if p not in ("self", "args", "kwargs")
            and not p.startswith("_")]


def docstring_problems(qualname: str, obj) -> list[str]:
    doc = inspect.getdoc(obj) or ""
    if not doc.strip():
        return [f"{qualname}: no docstring"]
    problems = []
    if re.search(r"\b20\d\d-\d\d-\d\d\b|before the fix|this session", doc):
        problems.append(f"{qualname}: a dated or development note in the docstring")
    if inspect.isclass(obj):
        if issubclass(obj, enum.Enum):
            return problems
        text = doc + (inspect.getdoc(obj.__init__) or "" if "__init__" in vars(obj) else "")
        missing = [f for f in constructor_fields(obj) if not named(f, text)]
        if missing:
            problems.append(f"{qualname}: constructor fields not named in the docstring: {missing}")
        return problems
    func = inspect.unwrap(obj)
    params = [p for p in inspect.signature(func).parameters if p != "self"]
    found = sections(doc)
    if params:
        if "Arguments" not in found:
            problems.append(f"{qualname}: no **Arguments:** section")
        else:
            missing = [p for p in params if not named(p, found["Arguments"])]
            if missing:
                problems.append(f"{qualname}: parameters not named under **Arguments:**: {missing}")
    body = own_body(func)
    if returns_value(body) and "Returns" not in found:
        problems.append(f"{qualname}: no **Returns:** section")
    if any(isinstance(n, ast.Raise) and not _not_implemented(n) for n in body) and "Raises" not in found:
        problems.append(f"{qualname}: raises, but has no **Raises:** section")
    return problems


def public_callables():
    """(qualified name, object) of every public function and class of both packages, and of the
    public methods their classes define (the API pages render those too)."""
    for mod in (pj, fitting):
        for qualname in sorted(public_names(mod)):
            obj = getattr(mod, qualname.split(".", 1)[1])
            if inspect.isclass(obj):
                yield qualname, obj
                if not issubclass(obj, enum.Enum):
                    for name, member in vars(obj).items():
                        if not name.startswith("_") and inspect.isfunction(member):
                            yield f"{qualname}.{name}", member
            elif inspect.isfunction(inspect.unwrap(obj)):
                yield qualname, obj


def test_every_public_docstring_has_its_sections():
    """Functions and methods: Arguments naming every parameter, Returns where a value is returned,
    Raises where the body raises. Classes: every constructor field named. No dated notes."""
    problems = []
    for qualname, obj in public_callables():
        problems += docstring_problems(qualname, obj)
    assert not problems, f"{len(problems)} docstring problems:\n" + "\n".join(problems)
