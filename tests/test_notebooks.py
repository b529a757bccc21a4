"""Notebook contract, smoke runs with small parameters, and reproduction of committed results.

The contract every ``notebooks/NN_<paper>_<topic>.ipynb`` follows:

- committed without outputs; the first cell is markdown with the chapter title (``# ...``);
- exactly one code cell tagged ``parameters``, assigning at least ``seed`` (int) and
  ``results_dir`` (str; ``""`` means the repository's ``results/``);
- it writes everything to ``calstudy.paths.results_path("<stem>", results_dir)``, i.e.
  ``<results_dir>/<stem>/`` (``results/<stem>/`` by default): tables ``*.csv``, figures ``*.png``,
  ``run.json`` and ``claims.csv``;
- ``notebooks/ci-params.yml`` holds small values: a flat mapping shared by all notebooks, in
  which a mapping under a notebook's stem overrides values for that notebook only.
"""

from __future__ import annotations

import ast
import json
from pathlib import Path

import nbformat
import numpy as np
import pandas as pd
import pytest
import yaml

from calstudy.paths import REPO_ROOT, RESULTS_DIR
from calstudy.results import VERDICTS, claim_ids, read_claims

NOTEBOOK_DIR = REPO_ROOT / "notebooks"
CI_PARAMS = NOTEBOOK_DIR / "ci-params.yml"
NOTEBOOKS = sorted(NOTEBOOK_DIR.glob("[0-9][0-9]_*.ipynb"))
NO_NOTEBOOK = pytest.param(
    None, marks=pytest.mark.skip(reason="notebooks/ holds no NN_*.ipynb notebook yet"), id="none"
)
ALL = [pytest.param(p, id=p.stem) for p in NOTEBOOKS] or [NO_NOTEBOOK]
# CSVs hold 6 significant digits (%.6g): one unit in the last digit is up to 1e-5 relative,
# which is what another machine's floating point may change; anything larger is a real change.
RTOL, ATOL = 2e-5, 1e-9

# The kernel papermill starts inherits these (the Makefile exports the same values).
REPRODUCIBLE_ENV = {
    "MPLBACKEND": "Agg",
    "OMP_NUM_THREADS": "1",
    "OPENBLAS_NUM_THREADS": "1",
    "MKL_NUM_THREADS": "1",
    "PYTHONHASHSEED": "0",
    "JUPYTER_PREFER_ENV_PATH": "1",
}


@pytest.fixture(autouse=True)
def reproducible_env(monkeypatch):
    for key, value in REPRODUCIBLE_ENV.items():
        monkeypatch.setenv(key, value)


def read(path: Path) -> nbformat.NotebookNode:
    return nbformat.read(path, as_version=4)


def parameter_cells(nb) -> list:
    return [c for c in nb.cells if "parameters" in c.get("metadata", {}).get("tags", [])]


def parameter_names(cell) -> set[str]:
    """Names assigned in a ``parameters`` cell."""
    return {
        t.id
        for node in ast.parse(cell.source).body
        if isinstance(node, ast.Assign | ast.AnnAssign)
        for t in (node.targets if isinstance(node, ast.Assign) else [node.target])
        if isinstance(t, ast.Name)
    }


def ci_parameters(stem: str) -> dict:
    if not CI_PARAMS.is_file():
        pytest.fail("notebooks/ci-params.yml is missing; it holds the small CI parameter values")
    data = yaml.safe_load(CI_PARAMS.read_text()) or {}
    params = {k: v for k, v in data.items() if not isinstance(v, dict)}
    params.update(data.get(stem) or {})
    return params


def run(path: Path, parameters: dict, tmp_path: Path) -> Path:
    """Execute ``path`` with papermill as ``make reproduce`` does; return its results folder."""
    import papermill

    papermill.execute_notebook(
        str(path),
        str(tmp_path / path.name),
        parameters=parameters,
        cwd=str(NOTEBOOK_DIR),
        progress_bar=False,
    )
    return Path(parameters["results_dir"]) / path.stem


def snapshot(folder: Path) -> dict:
    return {p.name: p.stat().st_mtime_ns for p in folder.glob("*")} if folder.is_dir() else {}


# ----------------------------------------------------------------------------------------------
# contract (fast)


@pytest.mark.parametrize("path", ALL)
def test_committed_without_outputs(path):
    nb = read(path)
    dirty = [
        i
        for i, c in enumerate(nb.cells)
        if c.cell_type == "code" and (c.get("outputs") or c.get("execution_count") is not None)
    ]
    assert not dirty, f"{path.name}: cells {dirty} hold outputs; clear them before committing"


@pytest.mark.parametrize("path", ALL)
def test_one_parameters_cell(path):
    cells = parameter_cells(read(path))
    assert len(cells) == 1, f"{path.name} has {len(cells)} cells tagged 'parameters'; expected 1"
    cell = cells[0]
    assert cell.cell_type == "code"
    names = parameter_names(cell)
    assert {"seed", "results_dir"} <= names, f"{path.name} parameters assign only {names}"


@pytest.mark.parametrize("path", ALL)
def test_title_cell(path):
    nb = read(path)
    first = nb.cells[0] if nb.cells else None
    assert first is not None and first.cell_type == "markdown"
    assert first.source.startswith("# "), f"{path.name} must open with a '# Title' markdown cell"
    titles = [
        line
        for c in nb.cells
        if c.cell_type == "markdown"
        for line in c.source.splitlines()
        if line.startswith("# ")
    ]
    assert len(titles) == 1, f"{path.name} has {len(titles)} level-1 headings; the book needs 1"


@pytest.mark.parametrize("path", ALL)
def test_listed_in_book(path):
    toc = yaml.safe_load((REPO_ROOT / "book" / "_toc.yml").read_text())
    assert f"notebooks/{path.stem}" in set(toc_files(toc)), f"{path.stem} missing in _toc.yml"


def toc_files(node):
    if isinstance(node, dict):
        for key, value in node.items():
            if key in ("file", "root"):
                yield value
            else:
                yield from toc_files(value)
    elif isinstance(node, list):
        for item in node:
            yield from toc_files(item)


def test_toc_lists_only_existing_files():
    if not NOTEBOOKS:
        pytest.skip("notebooks/ holds no NN_*.ipynb notebook yet (the toc already lists 01)")
    toc = yaml.safe_load((REPO_ROOT / "book" / "_toc.yml").read_text())
    for entry in toc_files(toc):
        if entry.startswith("notebooks/"):
            source = NOTEBOOK_DIR / f"{Path(entry).name}.ipynb"
        elif entry == "claims":
            source = REPO_ROOT / "src" / "calstudy" / "book.py"  # generated by make reproduce
        else:
            source = REPO_ROOT / "book" / f"{entry}.md"
        assert source.is_file(), f"_toc.yml lists {entry!r} but {source.name} does not exist"


def test_ci_script_runs_make_test():
    script = REPO_ROOT / ".ci" / "run"
    assert script.is_file() and script.stat().st_mode & 0o111
    text = script.read_text()
    assert "set -euo pipefail" in text and "make test" in text


# ----------------------------------------------------------------------------------------------
# runs (slow)


@pytest.mark.slow
@pytest.mark.parametrize("path", ALL)
def test_runs_with_ci_parameters(path, tmp_path):
    params = {**ci_parameters(path.stem), "results_dir": str(tmp_path / "results")}
    committed = snapshot(RESULTS_DIR / path.stem)
    out = run(path, params, tmp_path)
    assert snapshot(RESULTS_DIR / path.stem) == committed, "the run wrote to results/ itself"
    assert (out / "run.json").is_file() and (out / "claims.csv").is_file()
    # run.json records what produced the results: every parameter but where they went and
    # whether progress was shown
    recorded = set(json.loads((out / "run.json").read_text())["parameters"])
    wanted = parameter_names(parameter_cells(read(path))[0]) - {"results_dir", "progress"}
    assert wanted <= recorded, f"run.json lacks the parameters {sorted(wanted - recorded)}"
    claims = read_claims(out / "claims.csv")
    assert set(claims["verdict"]) <= set(VERDICTS)
    assert set(claims["id"]) <= set(claim_ids())
    assert (claims["notebook"] == path.stem).all()


def compare_tables(committed: Path, fresh: Path) -> None:
    old = pd.read_csv(committed, keep_default_na=False, na_values=[""])
    new = pd.read_csv(fresh, keep_default_na=False, na_values=[""])
    name = committed.relative_to(REPO_ROOT)
    assert list(new.columns) == list(old.columns), f"{name}: columns differ"
    assert len(new) == len(old), f"{name}: {len(new)} rows now, {len(old)} committed"
    for col in old.columns:
        a, b = old[col], new[col]
        if pd.api.types.is_numeric_dtype(a) and pd.api.types.is_numeric_dtype(b):
            np.testing.assert_allclose(
                b.to_numpy(float),
                a.to_numpy(float),
                rtol=RTOL,
                atol=ATOL,
                equal_nan=True,
                err_msg=f"{name}: column {col!r}",
            )
        else:
            assert b.astype(str).tolist() == a.astype(str).tolist(), f"{name}: column {col!r}"


@pytest.mark.slow
@pytest.mark.parametrize("path", ALL)
def test_default_run_reproduces_committed_results(path, tmp_path):
    committed_dir = RESULTS_DIR / path.stem
    if not (committed_dir / "claims.csv").is_file():
        pytest.skip(f"results/{path.stem}/ is not committed yet (run make reproduce)")
    out = run(path, {"results_dir": str(tmp_path / "results")}, tmp_path)
    committed = sorted(p.name for p in committed_dir.iterdir() if not p.name.startswith("."))
    missing = sorted(set(committed) - {p.name for p in out.iterdir()})
    assert not missing, f"the run did not produce committed files {missing}"
    for name in committed:
        if name.endswith(".csv"):
            compare_tables(committed_dir / name, out / name)
