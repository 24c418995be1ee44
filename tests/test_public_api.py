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


def _imports(package: str):
    """(file, line, module) of every ``from X import`` / ``import X`` in a package's sources."""
    import ast
    from pathlib import Path

    root = Path(__file__).resolve().parents[1] / package
    for f in sorted(root.rglob("*.py")):
        for node in ast.walk(ast.parse(f.read_text())):
            if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                yield f.name, node.lineno, node.module
            elif isinstance(node, ast.Import):
                for a in node.names:
                    yield f.name, node.lineno, a.name


def test_fitting_uses_only_the_public_and_internal_surfaces_of_pmpjax():
    """The layout's dependency rules: ``fitting`` reaches pmpjax through ``pmpjax`` and
    ``pmpjax.internal`` only (no private module), and ``pmpjax`` never imports ``fitting``."""
    private = [f"{f}:{n} {m}" for f, n, m in _imports("fitting") if m.startswith("pmpjax._")]
    assert not private, f"fitting imports private pmpjax modules: {private}"
    upward = [f"{f}:{n} {m}" for f, n, m in _imports("pmpjax") if m.split(".")[0] == "fitting"]
    assert not upward, f"pmpjax imports fitting: {upward}"
    import importlib
    import pkgutil

    for pkg in (pj, fitting):  # every module imports (a name missing from pmpjax.internal fails here)
        for m in pkgutil.walk_packages(pkg.__path__, pkg.__name__ + "."):
            if not m.name.endswith("__main__"):
                importlib.import_module(m.name)
