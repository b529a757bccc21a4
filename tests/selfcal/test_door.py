"""The selfcal door: the names the README documents, their docstrings, and the one call."""

from __future__ import annotations

import importlib
import inspect
import re
import warnings
from dataclasses import replace

import numpy as np
import pytest

import calstudy.selfcal as door
from calstudy import CalibrationError
from calstudy.core.errors import CalibrationWarning
from calstudy.core.paths import REPO_ROOT, data_path
from calstudy.models.robots import load_robot
from calstudy.selfcal import (
    base_parameters,
    cell_from_parameters,
    identify_cell,
    identify_measurements,
    parameter_report,
    parameters_from_robot,
    read_cell,
    validation_report,
)
from calstudy.selfcal.measured import subset
from calstudy.selfcal.model import default_model

EXAMPLE = data_path("selfcal", "example_measurements")
IMPORT = re.compile(r"from (calstudy\.[\w.]+) import ([\w, ]+)")


def _section(title: str) -> str:
    text = (REPO_ROOT / "README.md").read_text()
    start = text.index(f"## {title}")
    end = text.find("\n## ", start + 1)
    return text[start : end if end > 0 else len(text)]


def _imports(text: str) -> list[tuple[str, list[str]]]:
    return [(m, [n.strip() for n in names.split(",")]) for m, names in IMPORT.findall(text)]


def test_every_name_the_readme_imports_from_the_door_is_there():
    section = _section("Self-calibrate your own cell")
    old_rows, new_imports = [], []
    for line in section.splitlines():
        if line.startswith("| `from calstudy.papers.selfcal") or line.startswith("| `measured."):
            old, new = line.split(" | ")[:2]
            old_rows.append(old)
            new_imports += _imports(new)
    assert len(old_rows) >= 10, "the table of old imports and their doors is missing"
    new_imports += _imports(section.split("### Old imports")[0])
    door_names = set()
    for module, names in new_imports:
        assert module.startswith("calstudy.selfcal"), module
        mod = importlib.import_module(module)
        for name in names:
            assert hasattr(mod, name), f"{module} has no {name}"
            if module == "calstudy.selfcal":
                door_names.add(name)
                assert name in door.__all__, f"{name} is imported from the door but not in __all__"
    assert {"read_cell", "identify_cell", "suggest_poses", "ViewGeometry"} <= door_names
    # the old lines are old: the modules and names they import are gone from the paper
    for module, names in _imports(" ".join(old_rows)):
        if module == "calstudy.papers.selfcal":
            for name in names:
                with pytest.raises(ModuleNotFoundError):
                    importlib.import_module(f"{module}.{name}")
            continue
        try:
            mod = importlib.import_module(module)
        except ModuleNotFoundError:
            continue
        for name in names:
            home = getattr(mod, name, None)
            assert home is None or home.__module__.startswith("calstudy.selfcal."), (module, name)


def test_all_lists_exactly_the_public_names_the_door_binds():
    assert len(set(door.__all__)) == len(door.__all__)
    for name in door.__all__:
        assert getattr(door, name) is not None
    bound = {
        n for n, v in vars(door).items() if not n.startswith("_") and not inspect.ismodule(v)
    }
    assert bound == set(door.__all__)


SECTIONS = {
    "function": ("Parameters", "Returns", "Raises"),
    "class": ("Attributes",),
}


@pytest.mark.parametrize("name", [n for n in door.__all__ if n != "PARAM_NAMES"])
def test_every_public_name_of_the_door_has_numpydoc(name):
    obj = getattr(door, name)
    kind = "class" if inspect.isclass(obj) else "function"
    doc = inspect.getdoc(obj) or ""
    for heading in SECTIONS[kind]:
        assert re.search(rf"^{heading}\n-{{{len(heading)}}}$", doc, re.M), (name, heading)
    if kind == "function":
        names = {n for line in re.findall(r"^([\w, ]+) :", doc, re.M) for n in line.split(", ")}
        params = set(inspect.signature(obj).parameters)
        assert params <= names, (name, params - names)


def _quiet(fn, *args, **kwargs):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", CalibrationWarning)
        return fn(*args, **kwargs)


def test_one_call_from_a_folder_is_the_steps_a_user_took_by_hand():
    result = _quiet(identify_cell, EXAMPLE, requirement_mm=0.3)
    cell = read_cell(EXAMPLE)
    fit = _quiet(
        identify_measurements,
        cell.calibration,
        cell.start,
        cell.noise,
        pose_ids=cell.pose_ids["calibration"],
    )
    assert result.fit.params.tobytes() == fit.params.tobytes()
    assert result.fit.residuals.equals(fit.residuals)
    assert result.parameters.equals(parameter_report(fit, cell.start))
    kept = subset(cell.calibration, ~fit.outliers)
    assert fit.outliers.sum() == 2  # the example's planted outliers
    _, jac = default_model().points_and_jacobian(fit.params, kept.Q, kept.C)
    assert result.base.table.equals(base_parameters(jac, sigma_mm=fit.sigma_mm).table)
    table, summary = validation_report(cell.validation, cell.start, fit.params, 0.3)
    assert result.validation.equals(table) and result.validation_summary == summary
    assert result.validation_summary["requirement_mm"] == 0.3
    # a cell already read gives the same, its rows named by the cell's own pose ids
    ids = cell.pose_ids["calibration"] + 100
    again = _quiet(identify_cell, replace(cell, pose_ids={**cell.pose_ids, "calibration": ids}))
    assert again.fit.params.tobytes() == result.fit.params.tobytes()
    assert again.fit.residuals["pose"].tolist() == ids.tolist()


def test_the_named_frames_compose_into_the_identified_model():
    result = _quiet(identify_cell, EXAMPLE)
    cal = result.cell.calibration
    flange = result.robot.fk_many(cal.Q)
    chain = result.part2base @ flange @ result.sensor2flange
    points = np.einsum("mij,mj->mi", chain[:, :3, :3], cal.C) + chain[:, :3, 3]
    expected = default_model().points(result.fit.params, cal.Q, cal.C)
    assert np.abs(points - expected).max() < 1e-6
    # and the start: the declared frames of cell.toml
    assert not np.allclose(result.part2base, result.cell.part2base, atol=1e-3)


def test_cell_from_parameters_inverts_parameters_from_robot():
    robot = load_robot("fanuc_m710ic_50")
    rng = np.random.default_rng(4)
    part2base = np.eye(4)
    part2base[:3, 3] = [2500.0, -1200.0, -900.0]
    sensor2flange = np.eye(4)
    sensor2flange[:3, 3] = [0.0, -80.0, 120.0]
    params = parameters_from_robot(robot, part2base, sensor2flange)
    same, a, b = cell_from_parameters(robot, params)
    assert np.allclose(a, part2base, atol=1e-9) and np.allclose(b, sensor2flange, atol=1e-9)
    assert np.allclose(same.parameters(), robot.parameters(), atol=1e-12)
    moved = params + rng.normal(0.0, 1e-3, params.shape)
    assert np.allclose(parameters_from_robot(*cell_from_parameters(robot, moved)), moved, atol=1e-9)
    with pytest.raises(CalibrationError, match=r"parameters have shape \(29,\)"):
        cell_from_parameters(robot, params[:29])


def _without_validation():
    cell = read_cell(EXAMPLE)
    return replace(cell, validation=subset(cell.validation, np.zeros(len(cell.validation), bool)))


def test_a_cell_without_validation_rows_has_no_validation():
    result = _quiet(identify_cell, _without_validation())
    assert result.validation is None and result.validation_summary is None
    assert result.fit.n_identified == 30


@pytest.mark.parametrize("requirement", [0.0, -1.0, float("nan"), float("inf")])
def test_a_requirement_that_is_not_a_positive_length_is_refused(requirement):
    """Refused before the identification, with or without validation rows."""
    with pytest.raises(CalibrationError, match=rf"the requirement {requirement} mm must be"):
        identify_cell(_without_validation(), requirement_mm=requirement)


def test_a_missing_folder_is_named():
    with pytest.raises(FileNotFoundError, match="no_such_cell"):
        identify_cell(REPO_ROOT / "no_such_cell")


DOOR_METHODS = [
    f"{name}.{meth}"
    for name in door.__all__
    if inspect.isclass(getattr(door, name))
    for meth, fn in vars(getattr(door, name)).items()
    if not meth.startswith("_") and inspect.isfunction(fn)
]


@pytest.mark.parametrize("name", DOOR_METHODS)
def test_every_public_method_of_the_door_has_numpydoc(name):
    cls, meth = name.split(".")
    fn = getattr(getattr(door, cls), meth)
    doc = inspect.getdoc(fn) or ""
    params = [p for p in inspect.signature(fn).parameters if p != "self"]
    for heading in (["Parameters"] if params else []) + ["Returns", "Raises"]:
        assert re.search(rf"^{heading}\n-{{{len(heading)}}}$", doc, re.M), (name, heading)
    names = {n for line in re.findall(r"^([\w, ]+) :", doc, re.M) for n in line.split(", ")}
    assert set(params) <= names, (name, set(params) - names)
