"""What a notebook depends on (calstudy.io.dependencies): its paper's package, the modules these
import (the same as grimp's import graph finds), the data its modules read, and the same list in
run.json's digest."""

from __future__ import annotations

import ast
import functools
import json

import grimp
import pytest

from calstudy.core.errors import CalibrationError
from calstudy.core.paths import PACKAGE_DIR, REPO_ROOT
from calstudy.io import dependencies as deps
from calstudy.io.results import source_digest, source_files

NOTEBOOKS = sorted((REPO_ROOT / "notebooks").glob("[0-9][0-9]_*.ipynb"))
PAPERS = sorted(p.name for p in (PACKAGE_DIR / "papers").iterdir() if (p / "__init__.py").is_file())


def _labels(notebook) -> set[str]:
    return {deps.label(p) for p in deps.notebook_inputs(notebook)}


@pytest.fixture(scope="module")
def graph():
    return grimp.build_graph("calstudy", cache_dir=None)


@pytest.mark.parametrize("notebook", NOTEBOOKS, ids=lambda p: p.stem)
def test_the_closure_is_grimps(notebook, graph):
    """The modules reached from a notebook are those grimp's import graph reaches, with the
    packages holding each (an import runs their ``__init__`` first)."""
    tree = ast.parse(deps.notebook_code(notebook))
    paper = deps.notebook_paper(notebook)
    starts = deps.imported_modules(tree)
    if paper in PAPERS:
        starts |= {
            m for m in graph.modules if m.startswith(f"calstudy.papers.{paper}.")
        } | {f"calstudy.papers.{paper}"}
    todo, seen = set(starts), set()
    while todo:
        module = todo.pop()
        if module in seen:
            continue
        seen.add(module)
        parts = module.split(".")
        todo |= {".".join(parts[:i]) for i in range(1, len(parts))}
        todo |= graph.find_modules_directly_imported_by(module)
    assert deps.notebook_modules(notebook) == seen


def test_each_paper_package_is_in_its_notebooks_only():
    inputs = {nb.stem: _labels(nb) for nb in NOTEBOOKS}
    for paper in PAPERS:
        prefix = f"src/calstudy/papers/{paper}/"
        users = {stem for stem, files in inputs.items() if any(f.startswith(prefix) for f in files)}
        assert users == {stem for stem in inputs if deps.notebook_paper(REPO_ROOT / stem) == paper}
        # the whole package, not only the modules the notebook names
        package = {
            f"{prefix}{p.relative_to(PACKAGE_DIR / 'papers' / paper).as_posix()}"
            for p in (PACKAGE_DIR / "papers" / paper).rglob("*.py")
            if "__pycache__" not in p.parts
        }
        for stem in users:
            assert package <= inputs[stem], stem
    assert not any(f.startswith("src/calstudy/io/book") for f in set().union(*inputs.values()))


@functools.cache
def _data_named(path) -> set[str]:
    """Top-level names under data/ that a module names where it opens data: the first argument
    of ``scenario_file``/``data_path``, ``DATA_DIR / "name"``, or the paper's ``PAPER``."""
    tree = ast.parse(path.read_text())
    constants = {
        t.id: n.value.value
        for n in ast.walk(tree)
        if isinstance(n, ast.Assign) and isinstance(n.value, ast.Constant)
        for t in n.targets
        if isinstance(t, ast.Name)
    }

    def value(node):
        if isinstance(node, ast.Constant):
            return node.value
        return constants.get(node.id) if isinstance(node, ast.Name) else None

    named = set()
    for n in ast.walk(tree):
        if isinstance(n, ast.Call) and n.args:
            func = n.func.attr if isinstance(n.func, ast.Attribute) else getattr(n.func, "id", "")
            if func in ("scenario_file", "data_path"):
                named.add(value(n.args[0]))
        if isinstance(n, ast.BinOp) and isinstance(n.op, ast.Div):
            left = n.left.attr if isinstance(n.left, ast.Attribute) else getattr(n.left, "id", "")
            if left == "DATA_DIR":
                named.add(value(n.right))
    return {v for v in named if isinstance(v, str)}


@pytest.mark.parametrize("notebook", NOTEBOOKS, ids=lambda p: p.stem)
def test_the_data_its_modules_open_is_among_its_inputs(notebook):
    labels = _labels(notebook)
    data = {f.split("/")[1] for f in labels if f.startswith("data/")}
    for module in deps.notebook_modules(notebook):
        missing = _data_named(deps.module_file(module)) - data
        assert not missing, f"{module} opens data/{missing} and {notebook.stem} misses it"
    assert deps.notebook_paper(notebook) in data


@pytest.mark.parametrize("notebook", NOTEBOOKS, ids=lambda p: p.stem)
def test_run_json_digest_covers_the_same_files(notebook, tmp_path):
    assert [deps.label(p) for p in source_files(notebook)] == sorted(_labels(notebook))
    # the digest covers the notebook itself: a copy under another name has its own (that no
    # other paper's package is among its files: test_each_paper_package_is_in_its_notebooks_only)
    other = tmp_path / f"{notebook.stem[:3]}other_{notebook.name[3:]}"
    other.write_text(notebook.read_text())
    assert source_digest(notebook) != source_digest(other)


def test_make_rules():
    text = deps.make_rules(NOTEBOOKS[:1], "book/notebooks")
    target, _, body = text.splitlines()[1].partition(": ")
    assert target == f"book/notebooks/{NOTEBOOKS[0].name}"
    listed = set(" ".join(text.split("\n", 1)[1].split()).replace("\\", "").split()[1:])
    assert listed == _labels(NOTEBOOKS[0]) - {f"notebooks/{NOTEBOOKS[0].name}"}


def test_bad_notebooks_are_named(tmp_path):
    missing = tmp_path / "01_hybrid_x.ipynb"
    with pytest.raises(FileNotFoundError, match="01_hybrid_x.ipynb"):
        deps.notebook_inputs(missing)
    missing.write_text("not json")
    with pytest.raises(CalibrationError, match="01_hybrid_x.ipynb is not a Jupyter notebook"):
        deps.notebook_inputs(missing)
    source = ["%matplotlib inline\n", "import numpy\n", "import calstudy.core(\n"]
    missing.write_text(json.dumps({"cells": [{"cell_type": "code", "source": source}]}))
    with pytest.raises(CalibrationError, match="01_hybrid_x.ipynb: code line 2 is not Python"):
        deps.notebook_inputs(missing)
    assert deps.main([]) == 2
    assert deps.main(["book/notebooks", str(missing)]) == 1


def test_a_notebook_outside_the_papers(tmp_path):
    notebook = tmp_path / "my_cell.ipynb"
    cell = {"cell_type": "code", "source": "!pip list\nfrom calstudy.core import geometry\n"}
    notebook.write_text(json.dumps({"cells": [cell]}))
    assert deps.notebook_paper(notebook) == ""
    assert _labels(notebook) == {
        "my_cell.ipynb",
        "src/calstudy/__init__.py",
        "src/calstudy/core/__init__.py",
        "src/calstudy/core/errors.py",
        "src/calstudy/core/geometry.py",
    }


def test_a_paper_notebook_depends_on_its_whole_package(tmp_path):
    notebook = tmp_path / "07_dualarm_nothing_imported.ipynb"
    notebook.write_text(json.dumps({"cells": []}))
    package = {
        f"src/calstudy/papers/dualarm/{p.name}"
        for p in (PACKAGE_DIR / "papers" / "dualarm").glob("*.py")
    }
    labels = _labels(notebook)
    assert package <= labels
    assert {f for f in labels if f.startswith("data/")} >= {"data/dualarm/scenario.toml"}
    assert not any(f.startswith(("src/calstudy/papers/hybrid", "data/hybrid")) for f in labels)
