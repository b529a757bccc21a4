"""The library, the benchmarks and the notebooks use public names only: none imports a private
name (one with a leading underscore, dunders aside) of another module, of numpy or scipy, nor
reaches one through an imported module (``np.linalg._umath_linalg``, ``estimation._fit``). A name
a second module needs is public in its own home. (Tests may reach private helpers to test them.)
Nor does any of them, tests included, take a name from a module that only imports it (a
re-export): a name is imported from the module that defines it, or from a package's door."""

from __future__ import annotations

import ast
import functools
from pathlib import Path

import pytest
from support import REPO_ROOT

from calstudy.io.dependencies import module_file, notebook_code

SOURCE = REPO_ROOT / "src" / "calstudy"
NOTEBOOKS = REPO_ROOT / "notebooks"

#: private names still used, by file, each with its reason: statsmodels keeps the table of
#: Lilliefors p-values private (its public ``lilliefors`` tests one column per call, and the
#: vectorised test of every column at once needs the table itself)
ALLOWED = {"core/stats.py": {"statsmodels.stats._lilliefors"}}


def _private(name: str) -> bool:
    return name.startswith("_") and not (name.startswith("__") and name.endswith("__"))


def private_uses(tree: ast.Module) -> list[tuple[int, str]]:
    """(line, dotted name) of every private name of another module that ``tree`` imports or
    reaches as an attribute of a module it imported."""
    found: list[tuple[int, str]] = []
    modules: set[str] = set()  # local names bound to imported modules
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                parts = alias.name.split(".")
                found += [(node.lineno, alias.name) for p in parts if _private(p)][:1]
                modules.add(alias.asname or parts[0])
        elif isinstance(node, ast.ImportFrom):
            base = "." * node.level + (node.module or "")
            if any(_private(p) for p in (node.module or "").split(".")):
                found.append((node.lineno, base))
            for alias in node.names:
                if _private(alias.name):
                    found.append((node.lineno, f"{base}.{alias.name}"))
                else:
                    # a bound name may be a module (``from scipy import linalg``): follow it
                    modules.add(alias.asname or alias.name)
    for node in ast.walk(tree):
        if isinstance(node, ast.Attribute) and _private(node.attr):
            root = node.value
            while isinstance(root, ast.Attribute):
                root = root.value
            if isinstance(root, ast.Name) and root.id in modules:
                found.append((node.lineno, f"{ast.unparse(node.value)}.{node.attr}"))
    return sorted(set(found))


def _files() -> list[Path]:
    return sorted(p for p in SOURCE.rglob("*.py") if "__pycache__" not in p.parts)


@pytest.mark.parametrize("path", _files(), ids=lambda p: p.relative_to(SOURCE).as_posix())
def test_no_private_name_of_another_module(path):
    allowed = ALLOWED.get(path.relative_to(SOURCE).as_posix(), set())
    uses = private_uses(ast.parse(path.read_text(), filename=str(path)))
    assert not [u for u in uses if u[1] not in allowed], (
        f"{path.relative_to(REPO_ROOT)} uses private names: {uses}"
    )
    assert allowed <= {name for _, name in uses}, f"{allowed} is no longer used: drop it"


@pytest.mark.parametrize(
    "path",
    [*sorted((REPO_ROOT / "benchmarks").glob("*.py")), *sorted(NOTEBOOKS.glob("*.ipynb"))],
    ids=lambda p: p.name,
)
def test_benchmarks_and_notebooks_use_public_names(path):
    source = notebook_code(path) if path.suffix == ".ipynb" else path.read_text()
    uses = private_uses(ast.parse(source))
    assert not uses, f"{path.relative_to(REPO_ROOT)} uses private names: {uses}"


@pytest.mark.parametrize(
    ("source", "expected"),
    [
        ("from scipy.optimize import _minpack", [(1, "scipy.optimize._minpack")]),
        ("from numpy.linalg import _umath_linalg as u", [(1, "numpy.linalg._umath_linalg")]),
        ("import scipy.optimize._minpack", [(1, "scipy.optimize._minpack")]),
        ("from calstudy.io.results import _atomic_write, write_table",
         [(1, "calstudy.io.results._atomic_write")]),
        ("from calstudy.papers.hybrid import _experiments",
         [(1, "calstudy.papers.hybrid._experiments")]),
        ("import numpy as np\nnp.linalg._umath_linalg.solve1(a, b)",
         [(2, "np.linalg._umath_linalg")]),
        ("from calstudy.core import estimation\nestimation._fit(x)", [(2, "estimation._fit")]),
        # public names, dunders, and private attributes of objects (not modules) pass
        ("from __future__ import annotations\nimport numpy as np\nnp.__version__", []),
        ("def f(self):\n    return self._cache", []),
        ("from calstudy.io.results import atomic_write", []),
    ],
)
def test_the_check_finds_private_names(source, expected):
    assert private_uses(ast.parse(source)) == expected


def _module_file(module: str) -> Path | None:
    """The file of a ``calstudy`` module that is not a package (a package's ``__init__`` is a
    door and may re-export), or None."""
    path = module_file(module)
    return None if path is None or path.name == "__init__.py" else path


def defined_names(tree: ast.Module) -> set[str]:
    """Names a module defines at its top level (functions, classes, assignments, also inside a
    top-level ``if`` or ``try``); not the names it imports."""
    names: set[str] = set()
    for node in tree.body:
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef):
            names.add(node.name)
        elif isinstance(node, ast.Assign | ast.AnnAssign | ast.AugAssign | ast.If | ast.Try):
            for sub in ast.walk(node):
                if isinstance(sub, ast.FunctionDef | ast.ClassDef):
                    names.add(sub.name)
                elif isinstance(sub, ast.Name) and isinstance(sub.ctx, ast.Store):
                    names.add(sub.id)
    return names


def reexported_uses(tree: ast.Module, defined=None) -> list[tuple[int, str]]:
    """(line, dotted name) of every name ``tree`` takes from a calstudy module (not a door) that
    does not define it: imported from it, or reached as an attribute of it
    (``report.bin_distance`` where ``report`` only imports it); ``defined(module)`` gives a
    module's own names, None for a package."""
    if defined is None:
        defined = _own_names
    found = []
    modules: dict[str, str] = {}  # local name -> calstudy module (not a package) it is bound to
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("calstudy."):
            own = defined(node.module)
            for alias in node.names:
                sub = f"{node.module}.{alias.name}"
                if own is None and defined(sub) is not None:  # a module of a package
                    modules[alias.asname or alias.name] = sub
                elif own is not None and alias.name not in own:
                    found.append((node.lineno, sub))
        elif isinstance(node, ast.Import):
            for alias in node.names:
                if alias.asname and defined(alias.name) is not None:
                    modules[alias.asname] = alias.name
    for node in ast.walk(tree):
        if (
            isinstance(node, ast.Attribute)
            and isinstance(node.value, ast.Name)
            and node.value.id in modules
        ):
            module = modules[node.value.id]
            if node.attr not in defined(module) and not node.attr.startswith("__"):
                found.append((node.lineno, f"{module}.{node.attr}"))
    return sorted(set(found))


@functools.cache
def _own_names(module: str) -> frozenset[str] | None:
    path = _module_file(module)
    return None if path is None else frozenset(defined_names(ast.parse(path.read_text())))


def _all_files() -> list[Path]:
    return [*_files(), *sorted((REPO_ROOT / "tests").rglob("*.py")),
            *sorted((REPO_ROOT / "benchmarks").glob("*.py")), *sorted(NOTEBOOKS.glob("*.ipynb"))]


@pytest.mark.parametrize("path", _all_files(), ids=lambda p: p.relative_to(REPO_ROOT).as_posix())
def test_names_come_from_their_home(path):
    source = notebook_code(path) if path.suffix == ".ipynb" else path.read_text()
    uses = reexported_uses(ast.parse(source))
    assert not uses, f"{path.relative_to(REPO_ROOT)} imports names through a re-export: {uses}"


@pytest.mark.parametrize("path", _files(), ids=lambda p: p.relative_to(SOURCE).as_posix())
def test_a_module_exports_only_its_own_names(path):
    tree = ast.parse(path.read_text())
    exported = [
        elt.value
        for node in tree.body
        if isinstance(node, ast.Assign)
        and any(isinstance(t, ast.Name) and t.id == "__all__" for t in node.targets)
        for elt in node.value.elts
    ]
    if path.name != "__init__.py":
        assert set(exported) <= defined_names(tree), (
            f"{path.relative_to(REPO_ROOT)} lists names it does not define in __all__: "
            f"{sorted(set(exported) - defined_names(tree))}"
        )


@pytest.mark.parametrize(
    ("source", "expected"),
    [
        ("from calstudy.m import own, other", [(1, "calstudy.m.other")]),
        ("from calstudy.door import other", []),  # a door (package) may re-export
        ("from calstudy.m import own\nfrom numpy import other", []),
        # a module reached through its package, or imported under a name, then its attributes
        ("from calstudy.door import m\nm.own(m.other)", [(2, "calstudy.door.m.other")]),
        ("import calstudy.m as m\nm.other", [(2, "calstudy.m.other")]),
        ("from calstudy.door import m\nm.own\nx.other", []),
    ],
)
def test_the_check_finds_reexports(source, expected):
    homes = {"calstudy.m": {"own"}, "calstudy.door.m": {"own"}}  # calstudy.door: a package
    assert reexported_uses(ast.parse(source), homes.get) == expected
