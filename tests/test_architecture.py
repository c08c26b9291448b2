"""The package's import structure: layers point one way (down), no import cycles between
modules, and no ``_private`` name is used outside its package.

Layers (low to high); a module may import its own layer or any lower one:

    0 host:      jwarp.utils (atomic files, memory estimates),
                 jwarp.model (RobotModel, its parts and schema, the measurement interface;
                 it imports no importer: a robot file is read above it)
    1 importers: jwarp.importers (URDF/MJCF in, URDF out, sphere fitting: model and utils
                 only, plus third-party libs), and the plugin registry
                 jwarp.plugins.registry (robot names and files -> RobotModel; it loads the
                 plugins by name, and reads robot files through the importers)
    2 kernels:   jwarp.kernels (Warp only)
    3 core:      jwarp.core (arrays, device model, rows, limits)
    4 kinematics jwarp.kinematics
    5 world:     jwarp.world
    6 plugins:   jwarp.plugins (robots and measurements; loaded by the registry by name)
    7 solvers:   jwarp.solvers, jwarp.calibration
    8 learn:     jwarp.learn
    9 viz:       jwarp.viz
   10 cli:       jwarp.cli

The facade ``jwarp/__init__.py`` (and ``jwarp/__main__.py``) may import anything.
Imports inside functions count too (a lazy import is still a dependency), and so do
cycles through them. Imports under ``if TYPE_CHECKING:`` (annotations only, never run) count
for the layers and the private names but form no cycle: jwarp.model.schema and
jwarp.model.freeze annotate with the RobotModel that imports them. A ``_private`` name is private to its package (``jwarp.world``,
``jwarp.solvers``, ...): no module of another package imports or reads it.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1] / "jwarp"

LAYERS = {
    "jwarp.utils": 0, "jwarp.model": 0, "jwarp.importers": 1, "jwarp.plugins.registry": 1,
    "jwarp.kernels": 2, "jwarp.core": 3, "jwarp.kinematics": 4, "jwarp.world": 5,
    "jwarp.plugins": 6, "jwarp.solvers": 7, "jwarp.calibration": 7, "jwarp.learn": 8,
    "jwarp.viz": 9, "jwarp.cli": 10,
}
#: module paths removed in 0.2.0 (issue 40 item 8; CHANGELOG.md) -> where their code lives
#: (they forwarded there with a DeprecationWarning for one release after issue 28)
REMOVED = {
    "jwarp.atomic": "jwarp.utils.atomic", "jwarp.memory": "jwarp.utils.memory",
    "jwarp.registry": "jwarp.plugins.registry", "jwarp.measurement": "jwarp.model.measurement",
    "jwarp.solvers.planner": "jwarp.solvers.planning",
    "jwarp.solvers.rrt": "jwarp.solvers.planning.rrt",
    "jwarp.solvers.ik_explain": "jwarp.solvers.ik.explain",
    "jwarp.solvers.feasibility": "jwarp.world.path_feasibility",
    "jwarp.solvers.calibration": "jwarp.calibration",
    "jwarp.solvers.calibration.design": "jwarp.calibration.design.optimal",
    "jwarp.plugins.measurements.geometry": "jwarp.model.geometry",
    "jwarp.utils.deprecation": "",
    **{f"jwarp.solvers.calibration.{m}": f"jwarp.calibration.{p}{m}"
       for p, ms in (("estimate.", ("map", "options", "params", "origin", "elastic", "robust",
                                    "samples", "result", "diagnostics")),
                     ("design.", ("sensitivity", "poses", "tour", "tow", "virtual_noise")),
                     ("simulate.", ("campaign", "scenarios", "unmodeled")),
                     ("", ("files", "pool")))
       for m in ms},
}
FACADE = {"jwarp", "jwarp.__main__"}


def module_name(path: Path) -> str:
    rel = path.relative_to(ROOT.parent).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def layer_of(module: str) -> tuple[str, int]:
    best = ""
    for prefix in LAYERS:
        if (module == prefix or module.startswith(prefix + ".")) and len(prefix) > len(best):
            best = prefix
    if not best:
        raise AssertionError(f"module {module} belongs to no layer; add it to LAYERS")
    return best, LAYERS[best]


def package_of(module: str, is_package: bool) -> str:
    return module if is_package else module.rpartition(".")[0]


def modules() -> dict[str, tuple[Path, ast.Module, bool]]:
    out = {}
    for path in sorted(ROOT.rglob("*.py")):
        out[module_name(path)] = (path, ast.parse(path.read_text(), str(path)),
                                  path.name == "__init__.py")
    return out


MODULES = modules()


def _gen_api_facades() -> tuple[str, ...]:
    """tools/gen_api.py's FACADES (the one list of the public facades)."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("gen_api", ROOT.parent / "tools" / "gen_api.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod.FACADES


def resolve(module: str, is_package: bool, node: ast.ImportFrom) -> str:
    if node.level == 0:
        return node.module or ""
    base = package_of(module, is_package).split(".")
    base = base[:len(base) - (node.level - 1)]
    return ".".join(base + ([node.module] if node.module else []))


def imports(module: str) -> list[tuple[int, str, list[str], bool]]:
    """(line, imported module, imported names, at module level) of jwarp imports."""
    path, tree, is_pkg = MODULES[module]
    top = set(id(n) for n in tree.body)
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for a in node.names:
                if a.name == "jwarp" or a.name.startswith("jwarp."):
                    found.append((node.lineno, a.name, [], id(node) in top))
        elif isinstance(node, ast.ImportFrom):
            target = resolve(module, is_pkg, node)
            if target == "jwarp" or target.startswith("jwarp."):
                names = [a.name for a in node.names]
                # `from jwarp.x import y` where y is a submodule imports jwarp.x.y
                subs = [f"{target}.{n}" for n in names if f"{target}.{n}" in MODULES]
                if subs:
                    for s in subs:
                        found.append((node.lineno, s, [], id(node) in top))
                    names = [n for n in names if f"{target}.{n}" not in MODULES]
                    if not names:
                        continue
                found.append((node.lineno, target, names, id(node) in top))
    return found


def type_only_lines(module: str) -> set[int]:
    """The lines of the imports under ``if TYPE_CHECKING:`` (run by type checkers only)."""
    _, tree, _ = MODULES[module]
    lines = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and (
                (isinstance(node.test, ast.Name) and node.test.id == "TYPE_CHECKING")
                or (isinstance(node.test, ast.Attribute) and node.test.attr == "TYPE_CHECKING")):
            lines.update(n.lineno for stmt in node.body for n in ast.walk(stmt)
                         if isinstance(n, (ast.Import, ast.ImportFrom)))
    return lines


def test_every_module_has_a_layer():
    for m in MODULES:
        if m not in FACADE:
            layer_of(m)


def test_imports_point_down():
    bad = []
    for m in MODULES:
        if m in FACADE:
            continue
        _, mine = layer_of(m)
        for line, target, names, _ in imports(m):
            if target == "jwarp" and names and all(n.startswith("__") for n in names):
                continue  # __version__
            if target == "jwarp":
                bad.append(f"{m}:{line} imports the facade 'jwarp' (import the module instead)")
                continue
            owner, theirs = layer_of(target)
            if theirs > mine:
                bad.append(f"{m}:{line} imports {target} (layer {owner}={theirs} > {mine})")
    assert not bad, "upward imports:\n" + "\n".join(bad)


def test_the_model_reads_no_robot_file():
    """jwarp.model is the bottom: no module of it imports jwarp.importers or the plugin
    registry (jwarp.plugins.registry reads robot files through the importers; a robot
    name or path is resolved there, and the model below only receives a RobotModel). The
    layers say so too (importers and registry are layer 1); this names the arrow."""
    bad = [f"{m}:{line} imports {target}" for m in MODULES
           if m == "jwarp.model" or m.startswith("jwarp.model.")
           for line, target, _names, _top in imports(m)
           if target.startswith(("jwarp.importers", "jwarp.plugins"))]
    assert not bad, "jwarp.model imports an importer or the registry:\n" + "\n".join(bad)
    assert LAYERS["jwarp.importers"] > LAYERS["jwarp.model"]
    assert LAYERS["jwarp.plugins.registry"] > LAYERS["jwarp.model"]
    assert not hasattr(__import__("jwarp.model").model.RobotModel, "from_urdf")


def test_no_import_cycles():
    graph = {m: sorted({t for line, t, _, _ in imports(m)
                        if t in MODULES and t != m and line not in type_only_lines(m)})
             for m in MODULES}
    state: dict[str, int] = {}
    stack: list[str] = []
    cycles = []

    def visit(m: str) -> None:
        state[m] = 1
        stack.append(m)
        for t in graph[m]:
            if state.get(t) == 1:
                cycles.append(" -> ".join(stack[stack.index(t):] + [t]))
            elif t not in state:
                visit(t)
        stack.pop()
        state[m] = 2

    for m in graph:
        if m not in state:
            visit(m)
    assert not cycles, "import cycles:\n" + "\n".join(cycles)


def private_scope(module: str) -> str:
    """The package whose privates ``module`` may use: ``jwarp.world.motion`` ->
    ``jwarp.world`` (a top-level module such as ``jwarp.atomic`` is its own package)."""
    parts = module.split(".")
    return ".".join(parts[:2])


def test_private_scope():
    assert private_scope("jwarp.world.motion") == private_scope("jwarp.world") == "jwarp.world"
    assert private_scope("jwarp.solvers.ik.solver") != private_scope("jwarp.world.motion")


def test_no_private_name_crosses_a_package():
    bad = []
    for m, (_path, tree, is_pkg) in MODULES.items():
        aliases: dict[str, str] = {}
        for line, target, names, _ in imports(m):
            for n in names:
                if (n.startswith("_") and not n.startswith("__")
                        and private_scope(target) != private_scope(m)):
                    bad.append(f"{m}:{line} imports {target}.{n}")
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom):
                target = resolve(m, is_pkg, node)
                for a in node.names:
                    if f"{target}.{a.name}" in MODULES:
                        aliases[a.asname or a.name] = f"{target}.{a.name}"
            elif isinstance(node, ast.Import):
                for a in node.names:
                    if a.name in MODULES and a.asname:
                        aliases[a.asname] = a.name
        for node in ast.walk(tree):
            if (isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name)
                    and node.value.id in aliases and node.attr.startswith("_")
                    and not node.attr.startswith("__")):
                target = aliases[node.value.id]
                if private_scope(target) != private_scope(m):
                    bad.append(f"{m}:{node.lineno} uses {target}.{node.attr}")
    assert not bad, "private names used across packages:\n" + "\n".join(bad)


@pytest.mark.parametrize("name", ["World", "calibrate", "fk", "fk_elastic",
                                  "ik", "jacobian", "jacobian_dh", "plan", "Planner", "IKSolver", "robot",
                                  "robots",
                                  "RobotModel"])
def test_facade_exports(name):
    import jwarp

    assert hasattr(jwarp, name)


def test_api_doc_lists_the_facade():
    import jwarp

    text = (ROOT.parent / "docs" / "api.md").read_text()
    missing = [n for n in jwarp.__all__ if f"jwarp.{n}" not in text]
    assert not missing, f"docs/api.md does not list {missing}"


def test_tests_mirror_the_packages():
    """tests/<package>/ for jwarp's packages (and the benchmarks); basenames unique, so that
    pytest's rootdir-less imports cannot mix two test modules up."""
    tests = Path(__file__).resolve().parent
    packages = {p.name for p in ROOT.iterdir() if (p / "__init__.py").exists()} | {"benchmarks"}
    folders = {p.name for p in tests.iterdir() if p.is_dir() and not p.name.startswith((".", "_"))}
    assert folders <= packages, f"test folders without a package: {sorted(folders - packages)}"
    names = [p.name for p in tests.rglob("test_*.py")]
    assert len(names) == len(set(names)), sorted(n for n in names if names.count(n) > 1)


@pytest.mark.parametrize("func, options", [("ik", "jwarp.solvers.ik:IKOptions"),
                                           ("plan", "jwarp.solvers.planning:PlanOptions"),
                                           ("calibrate",
                                            "jwarp.calibration:CalibrationOptions")])
def test_options_are_spelled_once(func, options):
    """``jwarp.ik``/``plan``/``calibrate`` take ``options=None, **overrides``: no keyword
    re-lists a field of their options dataclass (issue 28: options spelled once)."""
    import dataclasses
    import importlib
    import inspect

    import jwarp

    mod, name = options.split(":")
    cls = getattr(importlib.import_module(mod), name)
    params = inspect.signature(getattr(jwarp, func)).parameters
    fields = {f.name for f in dataclasses.fields(cls)}
    relisted = sorted(fields & set(params))
    assert not relisted, f"jwarp.{func} re-lists fields of {name}: {relisted}"
    assert "options" in params and params["options"].default is None
    assert params["options"].kind is inspect.Parameter.KEYWORD_ONLY
    var_kw = [p.name for p in params.values() if p.kind is inspect.Parameter.VAR_KEYWORD]
    assert var_kw == ["overrides"], f"jwarp.{func}: expected **overrides, got {var_kw}"


def test_feasibility_helpers_come_from_their_module():
    """The planner re-exports the feasibility helpers it uses (``collision_free``,
    ``check_world``, ...) for old callers; jwarp's own modules import them from
    ``jwarp.world.path_feasibility``, where they live."""
    import jwarp.world.path_feasibility as feas

    helpers = {n for n in dir(feas) if not n.startswith("_") and callable(getattr(feas, n))
               and getattr(getattr(feas, n), "__module__", "") == feas.__name__}
    bad = [f"{m}:{line} imports {sorted(set(names) & helpers)} from jwarp.solvers.planning"
           for m in MODULES if m not in FACADE and m != "jwarp.solvers.planning"
           for line, target, names, _ in imports(m)
           if target == "jwarp.solvers.planning" and names and set(names) & helpers]
    assert not bad, "\n".join(bad)


def _device_defaults() -> list[str]:
    """``module:line name=default`` for every public function, method (``__init__``
    included) and dataclass field named ``device`` whose default is not None."""
    bad = []
    for m, (_, tree, _) in MODULES.items():
        for node in ast.walk(tree):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                if node.name.startswith("_") and node.name != "__init__":
                    continue
                a = node.args
                pos = a.posonlyargs + a.args
                pairs = list(zip(pos[len(pos) - len(a.defaults):], a.defaults))
                pairs += [(k, d) for k, d in zip(a.kwonlyargs, a.kw_defaults) if d is not None]
                for arg, default in pairs:
                    if arg.arg == "device" and not (isinstance(default, ast.Constant)
                                                    and default.value is None):
                        bad.append(f"{m}:{node.lineno} {node.name}(device={ast.unparse(default)})")
            elif isinstance(node, ast.ClassDef) and not node.name.startswith("_"):
                for st in node.body:
                    if (isinstance(st, ast.AnnAssign) and isinstance(st.target, ast.Name)
                            and st.target.id == "device" and st.value is not None
                            and not (isinstance(st.value, ast.Constant)
                                     and st.value.value is None)):
                        bad.append(f"{m}:{st.lineno} {node.name}.device = {ast.unparse(st.value)}")
    return bad


def test_one_device_default_rule():
    """Every public function, method and options dataclass of jwarp that takes a ``device``
    defaults it to None (issue 28: one device rule, docs/api.md "Devices"), and the
    facades' functions and classes say so in their signatures."""
    import importlib
    import inspect

    bad = _device_defaults()
    assert not bad, "device defaults other than None:\n" + "\n".join(bad)
    seen = 0
    for name in FACADES:
        mod = importlib.import_module(name)
        for attr in getattr(mod, "__all__", ()):
            obj = getattr(mod, attr)
            fn = obj.__init__ if inspect.isclass(obj) else obj
            if not callable(fn):
                continue
            try:
                params = inspect.signature(fn).parameters
            except (TypeError, ValueError):
                continue
            p = params.get("device")
            if p is not None:
                seen += 1
                assert p.default in (None, inspect.Parameter.empty), f"{name}.{attr}: {p}"
    assert seen >= 10


def test_devices_resolve_through_the_one_helper():
    """Only ``jwarp.core.arrays.resolve_device`` turns ``device=None`` into a device: no
    other module asks Warp for its preferred or default device (``put_model``, the Model's
    builder, resolves ``device=None`` to Warp's default device, the same rule)."""
    allowed = {"jwarp.core.arrays", "jwarp.core.device"}
    bad = []
    for m, (_, tree, _) in MODULES.items():
        if m in allowed:
            continue
        for node in ast.walk(tree):
            if (isinstance(node, ast.Attribute) and node.attr in ("get_preferred_device",
                                                                   "get_device")
                    and isinstance(node.value, ast.Name) and node.value.id == "wp"):
                bad.append(f"{m}:{node.lineno} wp.{node.attr}")
    assert not bad, "device resolved outside resolve_device:\n" + "\n".join(bad)


#: option dataclasses and the names the vocabulary replaced (issue 28; docs/api.md "Solvers")
OPTION_CLASSES = ["jwarp.solvers.ik:IKOptions", "jwarp.solvers.planning:PlanOptions",
                  "jwarp.calibration:CalibrationOptions", "jwarp.calibration:CampaignOptions",
                  "jwarp.calibration.design.optimal:DesignOptions",
                  "jwarp.calibration.design.poses:PoseOptions", "jwarp.solvers.planning.rrt:RRTOptions",
                  "jwarp.learn.plan_data:PlanDataOptions", "jwarp.learn.train_ik:TrainIKOptions",
                  "jwarp.learn.train_plan:TrainPlanOptions"]
OLD_OPTION_NAMES = {"max_iter", "max_iterations", "n_iter", "n_iterations", "n_seeds",
                    "initial", "early_stop"}


@pytest.mark.parametrize("path", OPTION_CLASSES)
def test_options_use_one_vocabulary(path):
    """No options dataclass has a field named as the vocabulary's replaced names
    (``iterations``, ``n_starts``, ``seeds``, ``start_kind``, ``freeze_solved`` /
    ``freeze_feasible`` / ``stop_when_solved``)."""
    import dataclasses
    import importlib

    mod, name = path.split(":")
    cls = getattr(importlib.import_module(mod), name)
    fields = {f.name for f in dataclasses.fields(cls)}
    assert not fields & OLD_OPTION_NAMES, f"{name}: {sorted(fields & OLD_OPTION_NAMES)}"
    from jwarp.solvers.overrides import renamed

    assert set(renamed(cls).values()) <= fields


def test_old_option_names_warn_and_give_the_same_options():
    """The replaced names work for one release: constructor, attribute and ``**overrides``
    warn (DeprecationWarning) and give the same options and the same result."""
    import numpy as np

    import jwarp
    from jwarp.calibration import CalibrationOptions
    from jwarp.calibration.design.optimal import DesignOptions
    from jwarp.solvers.ik import IKOptions
    from jwarp.solvers.planning import PlanOptions

    with pytest.warns(DeprecationWarning, match="'max_iterations' is renamed 'iterations'"):
        old = IKOptions(max_iterations=7)
    assert old == IKOptions(iterations=7)
    with pytest.warns(DeprecationWarning):
        assert old.max_iterations == 7
    with pytest.warns(DeprecationWarning):
        assert PlanOptions(initial="straight", early_stop=False) == PlanOptions(
            start_kind="straight", freeze_feasible=False)
    with pytest.warns(DeprecationWarning):
        assert CalibrationOptions(free="theta", max_iter=5) == CalibrationOptions(
            free="theta", equilibrium_iterations=5)
    with pytest.warns(DeprecationWarning):
        assert DesignOptions(n=3, max_iter=4) == DesignOptions(n=3, iterations=4)
    with pytest.raises(TypeError, match="both"):
        IKOptions(max_iterations=3, iterations=4)
    T = jwarp.fk("arm7", np.full(7, 0.3), device="cpu")[jwarp.robot("arm7").frame_index("tcp")]
    new = jwarp.ik("arm7", "tcp", T, iterations=20, n_starts=2, seed=1, device="cpu",
                   allow_no_collision=True)
    with pytest.warns(DeprecationWarning, match=r"ik\(\): 'max_iterations'"):
        again = jwarp.ik("arm7", "tcp", T, max_iterations=20, n_starts=2, seed=1, device="cpu",
                         allow_no_collision=True)
    np.testing.assert_array_equal(new.q, again.q)
    q0 = np.zeros((2, 7))
    with pytest.warns(DeprecationWarning, match="'initial' is renamed 'seeds'"):
        a = jwarp.ik("arm7", "tcp", T, initial=q0, iterations=5, device="cpu",
                     allow_no_collision=True)
    b = jwarp.ik("arm7", "tcp", T, seeds=q0, iterations=5, device="cpu", allow_no_collision=True)
    np.testing.assert_array_equal(a.q, b.q)


# ---------------------------------------------------------------- one Model, one name each
#: the removed names of the device model's tables (one name each now: ``put_model``,
#: ``DeviceModel``, ``DeviceModel.limits``, ``CollisionModel.model``)
OLD_TABLE_NAMES = {"KinematicsTables", "limit_tables"}
#: the loose joint-limit arrays that kernels took before ``kernels.path.LimitTables``
LOOSE_LIMIT_NAMES = {"lin_start", "lin_joint", "lin_coef", "lin_bounds"}
SOURCE_DIRS = ("jwarp", "tests", "benchmarks", "examples")


def _sources() -> dict[Path, ast.Module]:
    top = ROOT.parent
    return {p: ast.parse(p.read_text(), str(p)) for d in SOURCE_DIRS
            for p in sorted((top / d).rglob("*.py"))}


SOURCES = _sources()


def test_no_alias_names_of_the_old_tables():
    """No module of jwarp/, tests/, benchmarks/ or examples/ defines, imports or uses the
    old table names: ``KinematicsTables``, ``limit_tables``, a ``tables`` function of
    ``jwarp.core.device`` or a ``.tables`` attribute (the collision model's ``model``)."""
    bad = []
    for path, tree in SOURCES.items():
        where = path.relative_to(ROOT.parent)
        for node in ast.walk(tree):
            names: list[str] = []
            if isinstance(node, ast.Name):
                names = [node.id]
            elif isinstance(node, ast.Attribute):
                names = [node.attr]
                if node.attr == "tables":
                    bad.append(f"{where}:{node.lineno} uses the attribute .tables")
            elif isinstance(node, (ast.FunctionDef, ast.ClassDef)):
                names = [node.name]
            elif isinstance(node, ast.ImportFrom):
                names = [a.name for a in node.names] + [a.asname or "" for a in node.names]
                if (node.module or "").endswith("core.device") and any(
                        a.name == "tables" for a in node.names):
                    bad.append(f"{where}:{node.lineno} imports tables from jwarp.core.device")
            bad += [f"{where}:{node.lineno} names {n}" for n in names if n in OLD_TABLE_NAMES]
    import jwarp.core.device as device
    import jwarp.core.limits as limits

    for mod, name in ((device, "tables"), (device, "KinematicsTables"),
                      (limits, "limit_tables")):
        if hasattr(mod, name):
            bad.append(f"{mod.__name__} still has {name}")
    assert not bad, "\n".join(bad)


def _is_warp(decorator: ast.expr, kinds: set[str]) -> bool:
    """``@wp.kernel``, ``@wp.func``, ``@wp.kernel(...)`` etc. with the attribute in
    ``kinds``."""
    d = decorator.func if isinstance(decorator, ast.Call) else decorator
    return isinstance(d, ast.Attribute) and isinstance(d.value, ast.Name) \
        and d.value.id == "wp" and d.attr in kinds


def _is_array(annotation: ast.expr | None) -> bool:
    """An annotation ``wp.array(...)``, ``wp.array2d(...)``, ..."""
    return isinstance(annotation, ast.Call) and isinstance(annotation.func, ast.Attribute) \
        and annotation.func.attr.startswith("array")


def test_kernels_take_the_limits_as_one_struct():
    """Joint limits travel as one ``kernels.path.LimitTables`` struct: no Warp kernel or
    function takes the loose limit arrays (``lin_start``, ``lin_joint``, ``lin_coef``,
    ``lin_bounds``, or a ``limits`` array), and no struct but LimitTables holds them."""
    bad = []
    for path, tree in SOURCES.items():
        where = path.relative_to(ROOT.parent)
        for node in ast.walk(tree):
            if isinstance(node, ast.FunctionDef) and any(
                    _is_warp(d, {"kernel", "func"}) for d in node.decorator_list):
                for a in node.args.args:
                    if a.arg in LOOSE_LIMIT_NAMES or (a.arg == "limits"
                                                      and _is_array(a.annotation)):
                        bad.append(f"{where}:{node.lineno} {node.name}({a.arg}: a loose limit "
                                   f"array)")
            elif isinstance(node, ast.ClassDef) and node.name != "LimitTables" and any(
                    _is_warp(d, {"struct"}) for d in node.decorator_list):
                for item in node.body:
                    if isinstance(item, ast.AnnAssign) and isinstance(item.target, ast.Name) \
                            and item.target.id in LOOSE_LIMIT_NAMES:
                        bad.append(f"{where}:{item.lineno} struct {node.name} holds "
                                   f"{item.target.id}")
    assert not bad, "\n".join(bad)


# ------------------------------------------------------------------ packages by job
#: the packages each job lives in (issue 28)
PACKAGES = ("jwarp.model", "jwarp.utils", "jwarp.solvers.planning", "jwarp.solvers.ik",
            "jwarp.calibration", "jwarp.calibration.estimate", "jwarp.calibration.design",
            "jwarp.calibration.simulate", "jwarp.viz")
#: the public facades (the list tools/gen_api.py documents): each has ``__all__``, and
#: every name in it resolves
FACADES = _gen_api_facades()


def test_packages_by_job():
    """Each job in its package; no loose top-level module but the facade and ``__main__``;
    jwarp.solvers holds no calibration code."""
    for pkg in PACKAGES:
        assert pkg in MODULES and MODULES[pkg][2], f"{pkg} is not a package"
    loose = {m for m, (_p, _t, is_pkg) in MODULES.items()
             if m.count(".") == 1 and not is_pkg} - FACADE
    assert not loose, f"loose top-level modules: {sorted(loose)}"
    stale = [m for m in MODULES if m.startswith("jwarp.solvers.calibration")]
    assert not stale, stale


@pytest.mark.parametrize("facade", FACADES)
def test_facades_have_all(facade):
    import importlib

    mod = importlib.import_module(facade)
    names = getattr(mod, "__all__", None)
    assert names, f"{facade} has no __all__"
    assert len(names) == len(set(names)), f"{facade}.__all__ repeats a name"
    missing = [n for n in names if not hasattr(mod, n)]
    assert not missing, f"{facade}.__all__ names what it lacks: {missing}"


@pytest.mark.parametrize("old", sorted(REMOVED))
def test_removed_path_is_gone(old):
    """The old module paths that forwarded for one release are removed (0.2.0): importing
    one fails, and a removed top-level one is no attribute of the facade."""
    import importlib

    import jwarp

    assert old not in MODULES
    with pytest.raises(ModuleNotFoundError):
        importlib.import_module(old)
    if old.count(".") == 1:
        assert not hasattr(jwarp, old.split(".")[1]), old


def test_nothing_imports_a_removed_path():
    """jwarp's own modules, the tests, benchmarks, examples and tools import the new paths."""
    bad = [f"{m}:{line} imports {target}" for m in MODULES
           for line, target, _names, _top in imports(m) if target in REMOVED]
    repo = ROOT.parent
    for folder in ("tests", "benchmarks", "examples", "tools"):
        for path in sorted((repo / folder).rglob("*.py")):
            tree = ast.parse(path.read_text(), str(path))
            for node in ast.walk(tree):
                if isinstance(node, ast.ImportFrom) and node.level == 0:
                    targets = [node.module or ""] + [f"{node.module}.{a.name}" for a in node.names]
                elif isinstance(node, ast.Import):
                    targets = [a.name for a in node.names]
                else:
                    continue
                bad += [f"{path.relative_to(repo)}:{node.lineno} imports {t}" for t in targets
                        if t in REMOVED and path.name != "test_architecture.py"]
    assert not bad, "\n".join(bad)


# ------------------------------------------------------------ the robot resolved at the edge
#: the registry's ``robot`` (name, path or RobotModel -> RobotModel)
REGISTRY = "jwarp.plugins.registry"
#: calls of the registry's ``robot`` allowed below the edge: (module, function) -> why
ROBOT_LOOKUPS_ALLOWED: dict[tuple[str, str], str] = {}


def _dotted(node: ast.expr) -> str:
    parts = []
    while isinstance(node, ast.Attribute):
        parts.append(node.attr)
        node = node.value
    if not isinstance(node, ast.Name):
        return ""
    return ".".join([node.id] + parts[::-1])


def _robot_lookups(module: str) -> list[tuple[int, list[ast.AST]]]:
    """(line, enclosing classes and functions) of every call of the registry's ``robot`` in
    a module: through a name bound to it (``from jwarp.plugins.registry import robot as
    get_robot``, ``from jwarp import robot``) or as ``X.robot`` of a name bound to the
    registry module or to jwarp."""
    _path, tree, is_pkg = MODULES[module]
    names, mods = set(), {"jwarp.plugins.registry"}
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            target = resolve(module, is_pkg, node)
            for a in node.names:
                if a.name == "robot" and target in (REGISTRY, "jwarp"):
                    names.add(a.asname or a.name)
                elif f"{target}.{a.name}" == REGISTRY:
                    mods.add(a.asname or a.name)
        elif isinstance(node, ast.Import):
            for a in node.names:
                if a.name == "jwarp" or (a.name == REGISTRY and a.asname):
                    mods.add(a.asname or a.name)
    callees = names | {f"{m}.robot" for m in mods}
    found: list[tuple[int, list[ast.AST]]] = []

    def visit(node: ast.AST, scopes: list[ast.AST]) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, ast.Call) and _dotted(child.func) in callees:
                found.append((child.lineno, scopes))
            inner = scopes + [child] if isinstance(
                child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef, ast.Lambda)) else scopes
            visit(child, inner)

    visit(tree, [])
    return found


def _edge() -> tuple[set[tuple[str, str]], set[tuple[str, str]]]:
    """(functions, classes) as (module, qualname) named by a facade's ``__all__``."""
    import importlib
    import inspect

    funcs, classes = set(), set()
    for facade in FACADES:
        mod = importlib.import_module(facade)
        for name in mod.__all__:
            obj = getattr(mod, name)
            key = (getattr(obj, "__module__", None), getattr(obj, "__qualname__", None))
            if inspect.isclass(obj):
                classes.add(key)
            elif callable(obj):
                funcs.add(key)
    return funcs, classes


def test_robot_is_resolved_at_the_edge():
    """Issue 40 item 2: the robot is resolved once, at the edge. The registry's ``robot``
    (a name or path -> RobotModel) is called only by the CLI (jwarp.cli) and by the
    functions and classes a facade exports (``__all__``; a class's ``__init__`` and public
    methods), which accept a name, path or RobotModel; everything below them takes a
    RobotModel (or the device model built from it)."""
    funcs, classes = _edge()
    bad, allowed_seen = [], set()
    for module in MODULES:
        if module == REGISTRY or module == "jwarp.cli" or module.startswith("jwarp.cli."):
            continue
        for line, scopes in _robot_lookups(module):
            names = [getattr(s, "name", "<lambda>") for s in scopes]
            qual = ".".join(names)
            if (module, qual) in ROBOT_LOOKUPS_ALLOWED:
                allowed_seen.add((module, qual))
                continue
            if scopes and not isinstance(scopes[-1], ast.ClassDef):
                if (module, qual) in funcs:
                    continue
                if (len(scopes) == 2 and isinstance(scopes[0], ast.ClassDef)
                        and (module, names[0]) in classes
                        and (names[1] == "__init__" or not names[1].startswith("_"))):
                    continue
            bad.append(f"{module}:{line} in {qual or '<module>'}")
    assert not bad, ("the registry's robot() called below the edge (take a RobotModel; "
                     "the caller at the edge resolves it):\n" + "\n".join(bad))
    stale = set(ROBOT_LOOKUPS_ALLOWED) - allowed_seen
    assert not stale, f"ROBOT_LOOKUPS_ALLOWED lists calls that are gone: {sorted(stale)}"
