"""The public face: every entry point of ``pmpjax`` and ``fitting`` has a bad-input test.

A bad-input test is any test marked ``@pytest.mark.bad_input("pj.name", "fitting.name", ...)``
(in any ``tests/test_*.py``); it must check that a bad argument raises a clear error naming it.
This test fails when a public name is neither marked anywhere nor listed in ``NOT_ENTRY_POINTS``
(result containers, constants and abstract bases, which take no user input of their own).
"""

import ast
import inspect
from pathlib import Path

import fitting
import pmpjax as pj

TESTS = Path(__file__).parent

#: Result containers, constants, enums and abstract bases: constructed by the library, not users.
NOT_ENTRY_POINTS = {
    "pj.ArmEquilibrium", "pj.ArmTrajectory", "pj.Chain", "pj.DIRECTIONS", "pj.DondersSurface",
    "pj.Equilibrium", "pj.FIGURE3", "pj.Planner", "pj.SOLVERS", "pj.ReflexNetwork", "pj.Status", "pj.SmoothedPath",
    "pj.Subject", "pj.TARGET_RADIUS", "pj.Trajectory", "pj.HugmpSubject", "pj.DondersRecording",
    "pj.MOVEMENT_LABELS", "pj.PointingRecording", "pj.SyntheticPointing",
    "fitting.BlendFit", "fitting.BootstrapResult", "fitting.DondersFit", "fitting.HotellingResult",
    "fitting.IKWeightsLMResult", "fitting.IKWeightsResult", "fitting.LeastSquaresResult",
    "fitting.StiffnessFit", "fitting.PointingAnalysis", "fitting.PointingPrediction", "fitting.TimeConstantFit",
    "fitting.SweepResult",
    "fitting.PointingModelFit",
    "fitting.ReachingFit", "fitting.ReachingPrediction", "fitting.StiffnessFit",
    "fitting.MovementFit", "fitting.MovementPrediction",
}


def public_names():
    out = set()
    for mod, prefix in ((pj, "pj"), (fitting, "fitting")):
        for name in dir(mod):
            if name.startswith("_") or inspect.ismodule(getattr(mod, name)):
                continue
            out.add(f"{prefix}.{name}")
    return out


def _is_bad_input_mark(func) -> bool:
    return isinstance(func, ast.Attribute) and func.attr == "bad_input"


def marked_names():
    names = set()
    for path in TESTS.glob("test_*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Call) and _is_bad_input_mark(node.func):
                names.update(a.value for a in node.args if isinstance(a, ast.Constant))
    return names


def test_every_public_entry_point_has_a_bad_input_test():
    missing = sorted(public_names() - marked_names() - NOT_ENTRY_POINTS)
    assert not missing, f"public names without a @pytest.mark.bad_input test: {missing}"


def test_marks_name_real_public_names():
    unknown = sorted(marked_names() - public_names())
    assert not unknown, f"bad_input marks name things that are not public: {unknown}"


ROOT = TESTS.parent


def _module_name(path: Path, root: Path) -> str:
    parts = list(path.relative_to(root).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _bound_names(init: Path) -> set[str]:
    """Names a package's ``__init__.py`` binds by its imports (empty if there is none)."""
    if not init.exists():
        return set()
    return {(a.asname or a.name).split(".")[0] for node in ast.parse(init.read_text()).body
            if isinstance(node, ast.Import | ast.ImportFrom) for a in node.names}


def _imports(package: str, root: Path = ROOT):
    """``(module, line, imported)`` of every import in a package's sources, at any depth (imports
    inside functions too), relative imports resolved to absolute names (``from pkg import sub`` as
    ``pkg.sub`` when that is the module it binds)."""
    for f in sorted((root / package).rglob("*.py")):
        module = _module_name(f, root)
        base = module.split(".") if f.name == "__init__.py" else module.split(".")[:-1]
        for node in ast.walk(ast.parse(f.read_text())):
            if isinstance(node, ast.ImportFrom):
                target = node.module
                if node.level:
                    target = ".".join(base[: len(base) - node.level + 1] + ([node.module] if node.module else []))
                for a in node.names:  # ``from pkg import sub`` reaches module sub unless pkg binds the name
                    sub = root / Path(*f"{target}.{a.name}".split("."))
                    is_module = (sub.with_suffix(".py").exists() or (sub / "__init__.py").exists()) and \
                        a.name not in _bound_names(root / Path(*target.split(".")) / "__init__.py")
                    yield module, node.lineno, f"{target}.{a.name}" if is_module else target
            elif isinstance(node, ast.Import):
                for a in node.names:
                    yield module, node.lineno, a.name


def _modules(package: str, root: Path = ROOT) -> set[str]:
    return {_module_name(f, root) for f in (root / package).rglob("*.py")}


def _owner(target: str, modules: set[str]) -> str:
    """The module an import reaches: ``target`` itself, or the module it names an attribute of."""
    while target and target not in modules:
        target = target.rpartition(".")[0]
    return target


def _family(module: str) -> str | None:
    """``pkg._family`` for a module inside a family folder (``fitting._ik.weights`` ->
    ``fitting._ik``), else None (the package's faces ``pkg``, ``pkg.internal``)."""
    parts = module.split(".")
    return ".".join(parts[:2]) if len(parts) >= 2 and parts[1].startswith("_") and parts[1] != "__main__" else None


def _is_app(module: str) -> bool:
    return _family(module) in ("pmpjax._app", "fitting._app") or module.endswith("__main__")


def _app_imports(package: str, root: Path = ROOT) -> list[str]:
    """Imports of either package's application by a library module of ``package``."""
    return [f"{m}:{n} {t}" for m, n, t in _imports(package, root) if not _is_app(m)
            and any(t == a or t.startswith(a + ".") for a in ("pmpjax._app", "fitting._app"))]


def _private_family_imports(package: str, root: Path = ROOT) -> list[str]:
    """Imports of a family's module (not its face) from outside the family. The package's own
    surfaces (``package``, ``package.internal``, ``package.__main__``), which gather its public and
    internal names, may reach into families."""
    modules = _modules(package, root)
    surfaces = {package, f"{package}.internal", f"{package}.__main__"}
    found = []
    for m, n, t in _imports(package, root):
        owner = _owner(t, modules)
        fam = _family(owner)
        if fam and owner != fam and _family(m) != fam and m not in surfaces:
            found.append(f"{m}:{n} {owner}")
    return found


def _circles(package: str, root: Path = ROOT) -> list[list[str]]:
    """The strongly connected components (more than one module) of a package's import graph."""
    modules = _modules(package, root)
    graph = {m: set() for m in modules}
    for m, _, t in _imports(package, root):
        owner = _owner(t, modules)
        if owner and owner != m:
            graph[m].add(owner)
    index, low, stack, on, out = {}, {}, [], set(), []

    def visit(v):  # Tarjan's strongly connected components
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while not comp or comp[-1] != v:
                comp.append(stack.pop())
                on.discard(comp[-1])
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def test_fitting_uses_only_the_public_and_internal_surfaces_of_pmpjax():
    """The dependency rules between the packages: ``fitting``'s library reaches pmpjax through
    ``pmpjax`` and ``pmpjax.internal`` only, its application also through pmpjax's application
    face ``pmpjax._app`` (never one of its modules), and ``pmpjax`` never imports ``fitting``."""
    pm = _modules("pmpjax")
    private = [f"{m}:{n} {t}" for m, n, t in _imports("fitting") if t.split(".")[0] == "pmpjax"
               and _owner(t, pm) not in {"pmpjax", "pmpjax.internal", *(["pmpjax._app"] if _is_app(m) else [])}]
    assert not private, f"fitting imports private pmpjax modules: {private}"
    upward = [f"{m}:{n} {t}" for m, n, t in _imports("pmpjax") if t.split(".")[0] == "fitting"]
    assert not upward, f"pmpjax imports fitting: {upward}"
    import importlib
    import pkgutil

    for pkg in (pj, fitting):  # every module imports (a name missing from pmpjax.internal fails here)
        for m in pkgutil.walk_packages(pkg.__path__, pkg.__name__ + "."):
            if not m.name.endswith("__main__"):
                importlib.import_module(m.name)


def test_the_library_imports_nothing_from_the_application():
    """No library module (anything outside ``_app`` and ``__main__``, the faces included) imports
    the application of either package, and ``pmpjax.internal`` re-exports none of its names: the
    command line, the main job and its parts sit on top of the library."""
    found = _app_imports("pmpjax") + _app_imports("fitting")
    assert not found, f"library modules import the application: {found}"
    internal = [name for name in dir(pj.internal) if not name.startswith("__")
                and (getattr(getattr(pj.internal, name), "__module__", None) or "").startswith("pmpjax._app")]
    assert not internal, f"pmpjax.internal carries application names: {internal}"


def test_families_import_each_other_only_through_their_faces():
    """A module of one family of ``pmpjax`` or ``fitting`` (or of the application) imports another
    family through its ``__init__.py`` only, never one of its modules."""
    found = _private_family_imports("pmpjax") + _private_family_imports("fitting")
    assert not found, (f"imports of another family's private module (import the name from the family's face, "
                       f"adding it to that __init__.py if it is not there yet): {found}")


def test_benchmarks_use_public_and_internal_names_only():
    """Benchmarks import ``pmpjax``, ``fitting`` and their ``internal`` surfaces, never a private
    module (what they need beside the public API is named in ``pmpjax.internal`` /
    ``fitting.internal``)."""
    modules = _modules("pmpjax") | _modules("fitting")
    allowed = {"pmpjax", "pmpjax.internal", "fitting", "fitting.internal"}
    found = [f"{m}:{n} {t}" for m, n, t in _imports("benchmarks") if t.split(".")[0] in ("pmpjax", "fitting")
             and _owner(t, modules) not in allowed]
    assert not found, f"benchmarks import private modules: {found}"


def test_no_import_circles():
    """No two modules of a package import each other, directly or around a circle (imports inside
    functions count: a circle that only the order of calls keeps from failing is still one)."""
    circles = {package: _circles(package) for package in ("pmpjax", "fitting")}
    assert circles == {"pmpjax": [], "fitting": []}, f"import circles: {circles}"


def test_the_layering_checks_find_what_they_forbid(tmp_path):
    """On a small package that breaks every rule once, the checks above report exactly those
    imports (so an empty report on the real packages means something)."""
    files = {
        "__init__.py": "from ._a.x import f\n",  # the package's surfaces may reach into a family
        "internal.py": "from ._a.x import f\n",
        "_a/__init__.py": "from .x import f\n",
        "_a/x.py": "def f():\n    from .._b.y import g\n",  # a private module of family _b
        "_b/__init__.py": "",
        "_b/y.py": "from .._a import x\nfrom .._app import cli\n",  # _a's module x; the app
        "_app/__init__.py": "",
        "_app/cli.py": "from .. import _b\n",
    }
    for rel, text in files.items():
        (tmp_path / "fitting" / rel).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / "fitting" / rel).write_text(text)
    assert _circles("fitting", tmp_path) == [["fitting._a.x", "fitting._b.y"]]
    assert _app_imports("fitting", tmp_path) == ["fitting._b.y:2 fitting._app.cli"]
    assert _private_family_imports("fitting", tmp_path) == [
        "fitting._a.x:2 fitting._b.y", "fitting._b.y:1 fitting._a.x", "fitting._b.y:2 fitting._app.cli"]


def test_version_is_the_projects():
    """``pmpjax.__version__`` comes from the installed distribution's metadata, so it is the version
    pyproject.toml declares (a number written into the package would drift from it)."""
    import tomllib

    assert pj.__version__ == tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["version"]
