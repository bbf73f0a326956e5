"""The layer rule of the README's map, checked by parsing every import of the packages.

Layers, bottom to top; a module may import its own layer and those below, never above,
not even inside a function:

    0  opa core      opa._model, opa._system, opa._kernel, opa._run, opa._simulate, ...
    1  dynamics      opa.dynamics (sections, sweeps, orbits, Lyapunov, continuation)
    2  plots         opa.plots (matplotlib only)
    3  facade        opa (the package's public names) and opa.engine
    4  mc            Monte Carlo ensembles, the MC trajectory source
    5  compare       metrics, validation, trust map, reports, the paper's figures
    6  application   opa.cli (argparse; parses, calls the layers below, prints)

There is no exception. The application lives in ``opa/cli`` (the console script's home,
``opa-mc = opa.cli:main``) but is a layer of its own, above ``compare``: no module of the
packages imports it, and it takes only public names from the layers below.
"""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("opa", "mc", "compare")
LAYERS = ("opa core", "dynamics", "plots", "facade", "mc", "compare", "application")
#: the application layer: a package of its own in all but its folder
APPLICATION = "opa.cli"


def in_application(module: str) -> bool:
    return module == APPLICATION or module.startswith(APPLICATION + ".")


def module_name(path: Path) -> str:
    parts = path.relative_to(ROOT).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def modules() -> dict[str, Path]:
    found = {}
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            found[module_name(path)] = path
    return found


MODULES = modules()
# parsed once, at collection: CPython 3.11.7's ast.parse can fail with "AST constructor
# recursion depth mismatch" while threads of an earlier test (a Dask cluster shutting
# down) still compile code
TREES = {m: ast.parse(path.read_text(), filename=str(path)) for m, path in MODULES.items()}
#: the planted imports the checks must see, parsed at collection too
PLANTED = {
    "application": ast.parse(
        "from opa._run import run\nfrom opa import _kernel\nimport compare._findings\n"
        "from opa.dynamics._sweep import sweep\nfrom opa.cli._flags import say\n"
        "from . import _args\nfrom .._dataset import COMMAND\n"),
    "private": ast.parse("from opa._run import run\nfrom opa import _kernel\n"),
    "upward": ast.parse("from compare import _figures\n"),
}


def layer(module: str) -> int:
    if in_application(module):
        return LAYERS.index("application")
    if module.startswith("compare"):
        return LAYERS.index("compare")
    if module.startswith("mc"):
        return LAYERS.index("mc")
    if module in ("opa", "opa.engine"):
        return LAYERS.index("facade")
    if module.startswith("opa.plots"):
        return LAYERS.index("plots")
    if module.startswith("opa.dynamics"):
        return LAYERS.index("dynamics")
    assert module.startswith("opa._"), module
    return LAYERS.index("opa core")


def _resolve(importer: str, is_package: bool, node: ast.ImportFrom) -> list[str]:
    if node.level:
        base = importer.split(".") if is_package else importer.split(".")[:-1]
        base = base[: len(base) - (node.level - 1)]
        source = ".".join(base + ([node.module] if node.module else []))
    else:
        source = node.module or ""
    if source.split(".")[0] not in PACKAGES:
        return []
    targets = []
    for alias in node.names:  # `from opa import _kernel` imports the module opa._kernel
        sub = f"{source}.{alias.name}"
        targets.append(sub if sub in MODULES else source)
    return targets


def imports(module: str) -> list[tuple[str, bool]]:
    """(imported module of our packages, whether the import is inside a function)."""
    path = MODULES[module]
    tree = TREES[module]
    found = []

    def visit(node, nested):
        for child in ast.iter_child_nodes(node):
            inner = nested or isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef,
                                                 ast.Lambda))
            if isinstance(child, ast.Import):
                found.extend((a.name, inner) for a in child.names
                             if a.name.split(".")[0] in PACKAGES)
            elif isinstance(child, ast.ImportFrom):
                found.extend((t, inner) for t in
                             _resolve(module, path.name == "__init__.py", child))
            visit(child, inner)

    visit(tree, False)
    return found


def test_every_module_has_a_layer():
    assert len(MODULES) > 40
    for module in MODULES:
        assert 0 <= layer(module) < len(LAYERS)


def test_no_module_imports_upward():
    """Lazy imports included: no module may reach a higher layer, not even when called
    (``opa.sweep("mc")`` and ``opa.reproduce`` once did, through ``opa._shims``)."""
    upward = []
    for module in MODULES:
        for target, nested in imports(module):
            if layer(target) > layer(module):
                upward.append(f"{module} ({LAYERS[layer(module)]}) imports {target} "
                              f"({LAYERS[layer(target)]})")
    assert upward == []


def test_the_application_is_the_top_layer():
    """Nothing below imports ``opa.cli`` (though ``opa`` is its folder's package), and
    ``opa.cli`` reaches all three packages."""
    importers = sorted({m for m in MODULES if not in_application(m)
                        for t, _ in imports(m) if in_application(t)})
    assert importers == []
    reached = {t.split(".")[0] for m in MODULES if in_application(m) for t, _ in imports(m)}
    assert reached == {"opa", "mc", "compare"}


def strongly_connected(graph: dict[str, list[str]]) -> list[list[str]]:
    """Tarjan's strongly connected components of more than one node (the cycles)."""
    index, low, stack, on, cycles = {}, {}, [], set(), []

    def connect(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in graph[v]:
            if w not in index:
                connect(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                cycles.append(sorted(component))

    for v in graph:
        if v not in index:
            connect(v)
    return cycles


def test_the_kernel_has_one_caller():
    """``opa._run`` is the only module of the packages that imports the compiled kernel,
    beside ``opa._gpu``, which compiles the kernel's driver for a GPU and whose launches
    only ``opa._run`` makes (``opa.engine`` takes ``require`` from it: the device check
    itself lives with the other checks in ``opa._model``), and ``opa._forcefunction``,
    which has the kernel compile a user's force function with the kernel's signature
    (and runs nothing);
    everything else goes through ``_run``'s interface (``run``, ``run_batch``, ``Record``)."""
    importers = sorted(m for m in MODULES if any(t == "opa._kernel" for t, _ in imports(m)))
    assert importers == ["opa._forcefunction", "opa._gpu", "opa._run"]
    gpu_importers = sorted(m for m in MODULES if any(t == "opa._gpu" for t, _ in imports(m)))
    assert gpu_importers == ["opa._run", "opa.engine"]
    taken = {a.name for node in ast.walk(TREES["opa.engine"])
             if isinstance(node, ast.ImportFrom) and node.module == "opa._gpu"
             for a in node.names}
    assert taken == {"require"}


def _private_imports(module: str) -> list[str]:
    """The ``from X import name`` of ``module`` that reach into another package's private
    module (``opa._run``, ``opa.dynamics._sweep``, ``mc._ensemble``) or take a private
    name (``_choice``) from another package."""
    own = module.split(".")[0]
    found = []
    for node in ast.walk(TREES[module]):
        if not isinstance(node, ast.ImportFrom) or node.level or not node.module:
            continue
        parts = node.module.split(".")
        if parts[0] not in PACKAGES or parts[0] == own:
            continue
        if any(p.startswith("_") for p in parts[1:]):
            found.append(f"from {node.module} import ...")
        found += [f"{node.module}.{a.name}" for a in node.names if a.name.startswith("_")]
    return found


def _application_reaches(module: str) -> list[str]:
    """The imports of ``module`` that reach a private module (``opa._run``,
    ``opa.dynamics._sweep``, ``compare._findings``) or a private name (``from opa import
    _kernel``) outside the application ``opa.cli``."""
    found = []
    for node in ast.walk(TREES[module]):
        if isinstance(node, ast.Import):
            found += [f"import {a.name}" for a in node.names
                      if a.name.split(".")[0] in PACKAGES and not in_application(a.name)
                      and any(p.startswith("_") for p in a.name.split(".")[1:])]
        elif isinstance(node, ast.ImportFrom):
            name = node.module or ""
            if node.level:  # relative: from the module's package (its own, for __init__)
                path = MODULES.get(module)
                base = module.split(".")
                if path is None or path.name != "__init__.py":
                    base = base[:-1]
                base = base[: len(base) - (node.level - 1)]
                name = ".".join(base + ([node.module] if node.module else []))
            if name.split(".")[0] not in PACKAGES or in_application(name):
                continue
            if any(p.startswith("_") for p in name.split(".")[1:]):
                found.append(f"from {name} import ...")
            found += [f"{name}.{a.name}" for a in node.names if a.name.startswith("_")
                      and not in_application(f"{name}.{a.name}")]
    return found


def test_the_application_imports_public_names_only():
    """ARCHITECTURE.md: no private name imported outside its own package. ``opa.cli``
    takes ``opa``, ``opa.engine``, ``opa.dynamics``, ``opa.plots``, ``mc`` and
    ``compare``; its own private modules (``opa.cli._flags``) are its own."""
    found = {m: _application_reaches(m) for m in MODULES if in_application(m)}
    assert len(found) > 5
    assert {m: f for m, f in found.items() if f} == {}
    # the check sees planted private imports of every form, and passes the application's own
    TREES["opa.cli._planted"] = PLANTED["application"]
    try:
        assert _application_reaches("opa.cli._planted") == [
            "from opa._run import ...", "opa._kernel", "import compare._findings",
            "from opa.dynamics._sweep import ...", "from opa._dataset import ..."]
    finally:
        del TREES["opa.cli._planted"]


def test_packages_import_only_each_others_public_names():
    """``mc`` and ``compare`` reach ``opa`` through its public modules (``opa.engine``,
    ``opa.plots``, ``opa``) and ``compare`` reaches ``mc`` through ``mc``."""
    found = {m: _private_imports(m) for m in MODULES if not m.startswith("opa")}
    assert {m: f for m, f in found.items() if f} == {}
    # the check sees a planted private import
    TREES["planted"] = PLANTED["private"]
    try:
        assert _private_imports("planted") == ["from opa._run import ...", "opa._kernel"]
    finally:
        del TREES["planted"]


def test_no_import_cycles():
    """Every import counts, lazy ones included."""
    graph = {m: sorted({t for t, _ in imports(m) if t in MODULES and t != m}) for m in MODULES}
    assert strongly_connected(graph) == []


def test_the_checks_see_a_planted_cycle_and_a_planted_upward_import():
    graph = {"a": ["b"], "b": ["c"], "c": ["a"], "d": ["a"]}
    assert strongly_connected(graph) == [["a", "b", "c"]]
    tree = PLANTED["upward"]
    targets = _resolve("opa._kernel", False, tree.body[0])
    assert targets == ["compare._figures"]
    assert layer(targets[0]) > layer("opa._kernel")


def test_matplotlib_is_imported_only_by_figure_modules():
    drawing = {"opa.plots._diagrams", "opa.plots._branches", "opa.plots._stochastic",
               "compare._figures", "compare._mapfigures"}
    for module, path in MODULES.items():
        tree = TREES[module]
        top = [n for n in tree.body if isinstance(n, (ast.Import, ast.ImportFrom))]
        names = [a.name for n in top if isinstance(n, ast.Import) for a in n.names]
        names += [n.module for n in top if isinstance(n, ast.ImportFrom) and n.module]
        if any(name.split(".")[0] == "matplotlib" for name in names):
            assert module in drawing, f"{module} imports matplotlib at module level"


@pytest.mark.parametrize("package", ["opa", "mc", "compare", "opa.dynamics", "opa.cli"])
def test_importing_a_package_does_not_import_matplotlib(package):
    code = f"import sys, {package}; print('matplotlib' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, cwd=ROOT).stdout.strip()
    assert out == "False"


def test_one_name_one_meaning_for_module_constants():
    """No upper-case constant is defined in two modules (three different thresholds were
    once all called GRAZE_VELOCITY): a second module imports it or names its own."""
    defined: dict[str, list[str]] = {}
    for module, path in MODULES.items():
        for node in TREES[module].body:
            targets = (node.targets if isinstance(node, ast.Assign) else
                       [node.target] if isinstance(node, ast.AnnAssign) else [])
            for target in targets:
                if isinstance(target, ast.Name) and target.id.isupper() \
                        and not target.id.startswith("_"):
                    defined.setdefault(target.id, []).append(module)
    assert {name: where for name, where in defined.items() if len(where) > 1} == {}


def test_compare_imports_its_public_names_on_first_use():
    """``import compare`` imports none of its modules; each public name is there on first
    use, from the module that defines it."""
    code = ("import sys, compare; before = sorted(m for m in sys.modules "
            "if m.startswith('compare.')); names = [getattr(compare, n) for n in "
            "compare.__all__]; print(before, all(n is not None for n in names))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, cwd=ROOT).stdout.strip()
    assert out == "[] True"
