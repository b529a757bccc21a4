"""What a notebook's results depend on: the files whose bytes can change them.

A notebook ``NN_<paper>_<topic>.ipynb`` depends on

- itself;
- its paper's package ``calstudy.papers.<paper>`` (every module of it) and every calstudy module
  that its code cells or those modules import, directly or through others (an import inside a
  function counts), with the packages that hold them (their ``__init__`` runs first);
- its data: ``data/<paper>/``, and the shared tables that a module it runs reads
  (:data:`DATA_OF_MODULE`: ``data/claims.csv`` for :mod:`calstudy.claims`, ``data/robots/`` for
  :mod:`calstudy.models.robots`).

One list serves both ends: the Makefile reruns a notebook when one of its files changes
(``python -m calstudy.io.dependencies`` writes the rules, see :func:`main`), and ``run.json``'s
digest covers the same files (:func:`calstudy.io.results.source_digest`). An edit to one paper's
package thus reruns that paper's notebooks only. The module needs the standard library alone, so
that make can run it before the virtual environment exists.
"""

from __future__ import annotations

import ast
import json
import sys
from collections.abc import Iterable, Sequence
from pathlib import Path

from calstudy.core.errors import CalibrationError
from calstudy.core.paths import DATA_DIR, PACKAGE_DIR, REPO_ROOT

ROOT_PACKAGE = "calstudy"
PAPERS_PACKAGE = "calstudy.papers"

#: data under ``data/`` read by a shared module: it is an input of every notebook running it
DATA_OF_MODULE = {
    "calstudy.claims": ("claims.csv",),
    "calstudy.models.robots": ("robots",),
}


def label(path: Path) -> str:
    """How a file is named in make rules and digests.

    Parameters
    ----------
    path : pathlib.Path
        A file.

    Returns
    -------
    str
        ``path`` relative to the repository (``src/calstudy/...``, ``data/...``), else its name.
    """
    try:
        return path.resolve().relative_to(REPO_ROOT).as_posix()
    except ValueError:
        return path.name


def module_file(module: str) -> Path | None:
    """The file of a calstudy module.

    Parameters
    ----------
    module : str
        Dotted name, e.g. ``"calstudy.core.geometry"`` or ``"calstudy.papers.hybrid"``.

    Returns
    -------
    pathlib.Path or None
        ``.../core/geometry.py`` or ``.../papers/hybrid/__init__.py``; None if ``module`` is not
        a calstudy module (another package, or a name defined inside a module).
    """
    parts = module.split(".")
    if parts[0] != ROOT_PACKAGE:
        return None
    base = PACKAGE_DIR.joinpath(*parts[1:])
    for path in (base.with_suffix(".py"), base / "__init__.py"):
        if path.is_file():
            return path
    return None


def imported_modules(tree: ast.AST, module: str = "", is_package: bool = False) -> set[str]:
    """The calstudy modules that the import statements of ``tree`` name, anywhere in it
    (inside functions too).

    Parameters
    ----------
    tree : ast.AST
        Parsed source of a module or of a notebook's code.
    module : str, optional
        Dotted name of the importing module, to resolve relative imports.
    is_package : bool, optional
        True if ``module`` is a package (its ``__init__``).

    Returns
    -------
    set of str
        ``import p.q`` names ``p.q``; ``from p import name`` names ``p`` and ``p.name`` where
        that is a module. Only calstudy modules are kept.
    """
    found: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parent = module.split(".")
                parent = parent[: len(parent) - node.level + (1 if is_package else 0)]
                base = ".".join(parent + ([base] if base else []))
            found.add(base)
            found.update(f"{base}.{alias.name}" for alias in node.names)
    return {m for m in found if module_file(m) is not None}


def _parse(path: Path, what: str) -> ast.Module:
    try:
        return ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    except SyntaxError as exc:
        raise CalibrationError(f"{what} {label(path)} line {exc.lineno}: {exc.msg}") from None


#: imports of each module file read so far, by (path, size, modification time)
_IMPORTS: dict[tuple[Path, int, int], set[str]] = {}


def module_imports(module: str) -> set[str]:
    """The calstudy modules that a calstudy module imports (its file is read once per version).

    Parameters
    ----------
    module : str
        Dotted name of a calstudy module.

    Returns
    -------
    set of str
        See :func:`imported_modules`.

    Raises
    ------
    CalibrationError
        If ``module`` is not a calstudy module, or its file is not valid Python (the message
        names the file and line).
    """
    path = module_file(module)
    if path is None:
        raise CalibrationError(f"module {module!r} is not a calstudy module")
    stat = path.stat()
    key = (path, stat.st_size, stat.st_mtime_ns)
    if key not in _IMPORTS:
        tree = _parse(path, "module")
        _IMPORTS[key] = imported_modules(tree, module, path.name == "__init__.py")
    return _IMPORTS[key]


def module_closure(starts: Iterable[str]) -> set[str]:
    """Modules and every calstudy module they import, directly or through others.

    Parameters
    ----------
    starts : iterable of str
        Dotted names of calstudy modules.

    Returns
    -------
    set of str
        ``starts``, the modules they reach, and the packages that hold each (``calstudy.a.b``
        brings ``calstudy`` and ``calstudy.a``: importing it runs their ``__init__``).

    Raises
    ------
    CalibrationError
        As :func:`module_imports`.
    """
    todo, seen = set(starts), set()
    while todo:
        module = todo.pop()
        if module in seen:
            continue
        seen.add(module)
        parts = module.split(".")
        todo.update(".".join(parts[:i]) for i in range(1, len(parts)))
        todo.update(module_imports(module) - seen)
    return seen


def notebook_code(notebook: Path) -> str:
    """The code of a notebook's code cells.

    Parameters
    ----------
    notebook : pathlib.Path
        A Jupyter notebook (``.ipynb``).

    Returns
    -------
    str
        The code cells joined by new lines, without IPython's ``%`` magics and ``!`` shell lines.

    Raises
    ------
    CalibrationError
        If the file is not a JSON object.
    """
    try:
        cells = json.loads(notebook.read_text(encoding="utf-8")).get("cells", [])
    except (ValueError, AttributeError) as exc:
        raise CalibrationError(
            f"notebook {label(notebook)} is not a Jupyter notebook (JSON object): {exc}"
        ) from None
    lines = []
    for cell in cells:
        if cell.get("cell_type") == "code":
            source = cell.get("source", "")
            text = "".join(source) if isinstance(source, list) else str(source)
            lines += [ln for ln in text.splitlines() if not ln.lstrip().startswith(("%", "!"))]
    return "\n".join(lines)


def notebook_paper(notebook: Path) -> str:
    """The paper a notebook belongs to, by its name.

    Parameters
    ----------
    notebook : pathlib.Path
        A notebook ``NN_<paper>_<topic>.ipynb``.

    Returns
    -------
    str
        ``<paper>``; ``""`` for a name of another form.
    """
    parts = notebook.stem.split("_")
    return parts[1] if len(parts) > 2 and parts[0].isdigit() else ""


def _package_modules(package: str) -> set[str]:
    path = module_file(package)
    if path is None or path.name != "__init__.py":
        return set()
    return {
        ".".join((package, *p.relative_to(path.parent).with_suffix("").parts)).removesuffix(
            ".__init__"
        )
        for p in path.parent.rglob("*.py")
        if "__pycache__" not in p.parts
    }


def _data_files(parts: Sequence[str]) -> list[Path]:
    path = DATA_DIR.joinpath(*parts)
    if path.is_file():
        return [path]
    return [
        p
        for p in path.rglob("*")
        if p.is_file()
        and not any(s.startswith(".") or s == "__pycache__" for s in p.relative_to(DATA_DIR).parts)
    ]


def notebook_modules(notebook: Path) -> set[str]:
    """The calstudy modules a run of a notebook may execute: its paper's package and the
    modules these and the notebook's code cells reach (:func:`module_closure`).

    Parameters
    ----------
    notebook : pathlib.Path
        A notebook file.

    Returns
    -------
    set of str
        Dotted module names.

    Raises
    ------
    CalibrationError
        If the notebook is not JSON, or its code or a module is not valid Python.
    """
    tree = _parse_code(notebook)
    paper = notebook_paper(notebook)
    starts = imported_modules(tree) | _package_modules(f"{PAPERS_PACKAGE}.{paper}" if paper else "")
    return module_closure(starts)


def _parse_code(notebook: Path) -> ast.Module:
    try:
        return ast.parse(notebook_code(notebook), filename=str(notebook))
    except SyntaxError as exc:
        raise CalibrationError(
            f"notebook {label(notebook)}: code line {exc.lineno} is not Python: {exc.msg}"
        ) from None


def notebook_inputs(notebook: str | Path) -> list[Path]:
    """Every file ``notebook`` depends on: itself, its library modules and its data, sorted by
    :func:`label`.

    Parameters
    ----------
    notebook : str or pathlib.Path
        A notebook file ``NN_<paper>_<topic>.ipynb``.

    Returns
    -------
    list of pathlib.Path
        The files, each once.

    Raises
    ------
    FileNotFoundError
        If ``notebook`` is not a file.
    CalibrationError
        If the notebook is not valid JSON, or it or a library module is not valid Python (the
        message names the file and line).
    """
    notebook = Path(notebook)
    if not notebook.is_file():
        raise FileNotFoundError(f"notebook not found: {notebook}")
    modules = notebook_modules(notebook)
    files = {module_file(m) for m in modules} | {notebook}
    paper = notebook_paper(notebook)
    data = [(paper,)] if paper else []
    data += [(name,) for m, names in DATA_OF_MODULE.items() if m in modules for name in names]
    files.update(f for parts in data for f in _data_files(parts))
    return sorted({f.resolve() for f in files}, key=label)


def make_rules(notebooks: Sequence[str | Path], target_dir: str) -> str:
    """Make rules listing what each notebook depends on.

    Parameters
    ----------
    notebooks : sequence of str or pathlib.Path
        Notebook files.
    target_dir : str
        Folder of the executed copies, the rules' targets.

    Returns
    -------
    str
        One rule a notebook, ``<target_dir>/<notebook name>: <its inputs>`` (its inputs but
        the notebook itself, by :func:`label`), after a comment line.

    Raises
    ------
    FileNotFoundError, CalibrationError
        As :func:`notebook_inputs`.
    """
    out = ["# What each notebook depends on: python -m calstudy.io.dependencies (do not edit)"]
    for notebook in notebooks:
        path = Path(notebook)
        inputs = [label(p) for p in notebook_inputs(path) if p != path.resolve()]
        out.append(f"{target_dir}/{path.name}: " + " \\\n\t".join(inputs))
    return "\n".join(out) + "\n"


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m calstudy.io.dependencies TARGET_DIR NOTEBOOK...``: print :func:`make_rules`.

    Parameters
    ----------
    argv : sequence of str, optional
        The arguments (default: the command line's).

    Returns
    -------
    int
        Exit status: 0, 1 on a missing or unreadable notebook or module (the message goes to
        standard error), 2 without arguments.
    """
    args = list(sys.argv[1:] if argv is None else argv)
    if len(args) < 2:
        print("usage: python -m calstudy.io.dependencies TARGET_DIR NOTEBOOK...", file=sys.stderr)
        return 2
    try:
        sys.stdout.write(make_rules(args[1:], args[0]))
    except (CalibrationError, FileNotFoundError) as exc:
        print(f"calstudy.io.dependencies: {exc}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
