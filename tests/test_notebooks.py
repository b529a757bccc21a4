"""Notebook contract, smoke runs with small parameters, and reproduction of committed results.

The contract every ``notebooks/NN_<paper>_<topic>.ipynb`` follows:

- committed without outputs; the first cell is markdown with the chapter title (``# ...``);
- exactly one code cell tagged ``parameters``, assigning at least ``seed`` (int) and
  ``results_dir`` (str; ``""`` means the repository's ``results/``);
- it writes everything to ``calstudy.core.paths.results_path("<stem>", results_dir)``, i.e.
  ``<results_dir>/<stem>/`` (``results/<stem>/`` by default): tables ``*.csv``, figures ``*.png``,
  ``run.json`` and, if its paper (``NN_<paper>_...``) has claims in ``data/claims.csv``,
  ``claims.csv`` (a notebook such as ``06_handeye_your_cell`` decides no claim and writes none);
- ``notebooks/ci-params.yml`` holds small values: one mapping per notebook, under its stem.
"""

from __future__ import annotations

import ast
import json
from pathlib import Path

import nbformat
import pytest
import yaml
from support import REPRODUCIBLE_ENV, assert_same_table, ci_parameters, run

from calstudy.claims import VERDICTS, claim_ids
from calstudy.core.paths import REPO_ROOT, RESULTS_DIR
from calstudy.io.results import EXECUTION_PARAMETERS, read_claims

NOTEBOOK_DIR = REPO_ROOT / "notebooks"
CI_PARAMS = NOTEBOOK_DIR / "ci-params.yml"
NOTEBOOKS = sorted(NOTEBOOK_DIR.glob("[0-9][0-9]_*.ipynb"))
ALL = [pytest.param(p, id=p.stem) for p in NOTEBOOKS]



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




def decides_claims(stem: str) -> bool:
    """True if the paper of notebook ``stem`` (``NN_<paper>_<topic>``) has registered claims."""
    paper = stem.split("_")[1]
    return any(cid.split(".")[0] == paper for cid in claim_ids())


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
def test_papermill_infers_every_parameter(path):
    """papermill reads the parameters cell with a regular expression that a ``=`` in a comment
    derails; a parameter it does not see is refused with "Passed unknown parameter"."""
    import papermill

    cell = parameter_cells(read(path))[0]
    missed = parameter_names(cell) - set(papermill.inspect_notebook(str(path)))
    assert not missed, f"{path.name}: papermill does not see the parameters {sorted(missed)}"


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


def test_toc_lists_exactly_the_chapters_and_notebooks():
    """The book's table of contents and the sources agree both ways: nothing listed is missing
    and no notebook or chapter is left out (``claims`` is generated by ``make reproduce``)."""
    toc = yaml.safe_load((REPO_ROOT / "book" / "_toc.yml").read_text())
    listed = list(toc_files(toc))
    assert len(listed) == len(set(listed)), f"_toc.yml lists an entry twice: {listed}"
    sources = {f"notebooks/{p.stem}" for p in NOTEBOOKS}
    # fragments the chapters include (``make reproduce`` writes them, git ignores them)
    fragments = ("claims", "claims-headline", "verdicts-")
    sources |= {
        p.stem for p in (REPO_ROOT / "book").glob("*.md") if not p.stem.startswith(fragments)
    }
    sources |= {"claims", "ledger"}  # generated pages
    assert set(listed) == sources, (
        f"only in _toc.yml: {sorted(set(listed) - sources)}; "
        f"not in _toc.yml: {sorted(sources - set(listed))}"
    )



# ----------------------------------------------------------------------------------------------
# runs (slow)


@pytest.mark.slow
@pytest.mark.parametrize("path", ALL)
def test_runs_with_ci_parameters(path, ci_runs):
    ci_parameters(path.stem)  # fails if ci-params.yml lacks the notebook
    ci = ci_runs[path.stem]  # run once per session (conftest.py), also built into the book
    assert not ci.error, ci.error
    assert not ci.touched_repository_results, "the run wrote to results/ itself"
    out = ci.results
    assert (out / "run.json").is_file()
    assert (out / "claims.csv").is_file() == decides_claims(path.stem), "claims.csv presence"
    # run.json records what produced the results: every parameter but those saying how the
    # run was executed (workers, scheduler, cache, progress, where results went)
    recorded = set(json.loads((out / "run.json").read_text())["parameters"])
    wanted = parameter_names(parameter_cells(read(path))[0]) - set(EXECUTION_PARAMETERS)
    assert not recorded & set(EXECUTION_PARAMETERS), "run.json must not depend on n_jobs etc."
    assert wanted <= recorded, f"run.json lacks the parameters {sorted(wanted - recorded)}"
    if not decides_claims(path.stem):
        return
    claims = read_claims(out / "claims.csv")
    assert set(claims["verdict"]) <= set(VERDICTS)
    assert set(claims["id"]) <= set(claim_ids())
    assert (claims["notebook"] == path.stem).all()


def compare_tables(committed: Path, fresh: Path) -> None:
    assert_same_table(fresh, committed)

@pytest.mark.verify
@pytest.mark.parametrize("path", ALL)
def test_default_run_reproduces_committed_results(path, tmp_path):
    committed_dir = RESULTS_DIR / path.stem
    if not (committed_dir / "run.json").is_file():
        pytest.skip(f"results/{path.stem}/ is not committed yet (run make reproduce)")
    out = run(path, {"results_dir": str(tmp_path / "results")}, tmp_path)
    committed = sorted(p.name for p in committed_dir.iterdir() if not p.name.startswith("."))
    missing = sorted(set(committed) - {p.name for p in out.iterdir()})
    assert not missing, f"the run did not produce committed files {missing}"
    for name in committed:
        if name.endswith(".csv"):
            compare_tables(committed_dir / name, out / name)
