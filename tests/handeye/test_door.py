"""The hand-eye door: every name the README documents is importable from ``calstudy.handeye`` and
listed in its ``__all__``; every public function and method of the door has numpydoc sections;
the user's entry point is a plain function with keyword options and a frozen, frame-named
result."""

from __future__ import annotations

import ast
import dataclasses
import inspect
import re

import numpy as np
import pytest
from support import REPO_ROOT, handeye_cell

import calstudy.handeye as door


def _readme_door_names() -> set[str]:
    """Names the README imports from the door (``from calstudy.handeye import ...`` in its code
    and in the table of old and new imports) and lists in backticks as importable from it."""
    text = (REPO_ROOT / "README.md").read_text()
    names: set[str] = set()
    for match in re.finditer(r"from calstudy\.handeye import (\w+(?:, \w+)*)", text):
        names |= set(match.group(1).split(", "))
    intro = r"importable from `calstudy.handeye` \(its `__all__`\):(.*?)\.\n"
    listed = re.search(intro, text, re.S)
    assert listed, "the README's list of the door's names"
    names |= set(re.findall(r"`(\w+)`", listed.group(1)))
    return names


def test_every_documented_name_comes_from_the_door():
    names = _readme_door_names()
    assert {"read_pose_list", "calibrate_handeye", "HandEyeResult"} <= names
    for name in sorted(names):
        assert name in door.__all__, name
        namespace: dict = {}
        exec(f"from calstudy.handeye import {name}", namespace)
        assert namespace[name] is getattr(door, name)


def test_all_is_complete_and_documented():
    assert len(set(door.__all__)) == len(door.__all__)
    assert set(door.__all__) == _readme_door_names()
    public = {n for n in vars(door) if not n.startswith("_")}
    submodules = {n for n in public if inspect.ismodule(getattr(door, n))}
    assert public - submodules - {"annotations"} == set(door.__all__)


def _public_callables():
    for name in door.__all__:
        obj = getattr(door, name)
        if inspect.isfunction(obj):
            yield name, obj
        elif inspect.isclass(obj):
            for meth, fn in vars(obj).items():
                if not meth.startswith("_") and inspect.isfunction(fn):
                    yield f"{name}.{meth}", fn


@pytest.mark.parametrize("name, fn", list(_public_callables()), ids=lambda v: str(v)[:40])
def test_numpydoc_sections(name, fn):
    doc = inspect.getdoc(fn) or ""
    params = [p for p in inspect.signature(fn).parameters if p != "self"]
    wanted = (["Parameters"] if params else []) + ["Returns", "Raises"]
    for section in wanted:
        assert re.search(rf"^{section}\n-+$", doc, re.M), f"{name}: no {section} section"
    if params:
        block = doc.split("Parameters\n", 1)[1].split("\n\n", 1)[0] + doc
        for p in params:
            assert re.search(rf"\b{p}\b", block), f"{name}: parameter {p} undocumented"


def test_calibrate_handeye_is_a_plain_function_with_keyword_options():
    for fn in (door.calibrate_handeye, door.calibrate_robot_world_handeye):
        assert inspect.isfunction(fn) and fn.__closure__ is None
        assert fn.__module__ == "calstudy.handeye.calibrate"
        assert fn.__qualname__ == fn.__code__.co_name  # defined by its own def
        tree = ast.parse(inspect.getsource(fn))
        assert isinstance(tree.body[0], ast.FunctionDef)
        kinds = [p.kind for p in inspect.signature(fn).parameters.values()]
        assert kinds[:2] == [inspect.Parameter.POSITIONAL_OR_KEYWORD] * 2
        assert set(kinds[2:]) == {inspect.Parameter.KEYWORD_ONLY}


def test_result_is_frozen_and_named_by_frames():
    cell = handeye_cell(1, noise=False)
    res = door.calibrate_handeye(cell.flange2base, cell.target2camera)
    fields = {f.name for f in dataclasses.fields(res)}
    assert {"camera2flange", "target2base", "camera2base", "target2flange"} <= fields
    assert not fields & {"x", "z", "x_name", "z_name"}
    with pytest.raises(dataclasses.FrozenInstanceError):
        res.camera2flange = np.eye(4)
    assert res.camera2mount is res.camera2flange and res.target2mount is res.target2base
    assert door.SETUP_FRAMES[res.setup] == ("camera2flange", "target2base")
