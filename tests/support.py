"""Helpers shared by several test modules (on pytest's ``pythonpath``)."""

from __future__ import annotations

import dataclasses
import io
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml

from calstudy.core.paths import REPO_ROOT
from calstudy.handeye.simulate import simulate_cell
from calstudy.models.targets import ManufacturedHoleTarget
from calstudy.papers.hybrid import simulate

NOTEBOOK_DIR = REPO_ROOT / "notebooks"
CI_PARAMS = NOTEBOOK_DIR / "ci-params.yml"

# The kernel papermill starts inherits these (the Makefile exports the same values).
REPRODUCIBLE_ENV = {
    "MPLBACKEND": "Agg",
    "OMP_NUM_THREADS": "1",
    "OPENBLAS_NUM_THREADS": "1",
    "MKL_NUM_THREADS": "1",
    "PYTHONHASHSEED": "0",
    "JUPYTER_PREFER_ENV_PATH": "1",
}


def ci_parameters(stem: str) -> dict:
    """The small CI values of notebook ``stem``: its own mapping in ``notebooks/ci-params.yml``."""
    if not CI_PARAMS.is_file():
        pytest.fail("notebooks/ci-params.yml is missing; it holds the small CI parameter values")
    data = yaml.safe_load(CI_PARAMS.read_text()) or {}
    stray = sorted(k for k, v in data.items() if not isinstance(v, dict))
    if stray:
        pytest.fail(f"ci-params.yml has top-level values {stray}; put them under a notebook stem")
    if stem not in data:
        pytest.fail(f"ci-params.yml has no mapping for {stem}")
    return dict(data[stem])


def disk_image(size=41, radius=9.0, centre=(20.3, 19.6), blur=0.0):
    """A float32 ROI ``(size, size)``: a bright anti-aliased disc (0.9) on 0.1, optionally
    blurred by a circle of confusion of ``blur`` px (binocular Eq. 7)."""
    from calstudy.models.optics import defocus

    yy, xx = np.mgrid[0:size, 0:size]
    d = np.hypot(xx - centre[0], yy - centre[1])
    img = np.clip(radius + 0.5 - d, 0, 1).astype(np.float32) * 0.8 + 0.1
    return defocus(img, blur) if blur else img


def binocular_rig():
    """The binocular sensor of Table 1 (``data/binocular/sensor.toml``) as a StereoRig."""
    from calstudy.papers.binocular.scenario import load_scenario

    return load_scenario().rig


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


def ideal_station(seed=0, robot_errors=False):
    """A hybrid station with every noise source off and a perfectly made target."""
    rng = np.random.default_rng(seed)
    s = simulate.make_station(
        rng, robot_errors=robot_errors, sigma_point_mm=0.0, pixel_sigma=0.0, repeatability_mm=0.0
    )
    perfect = ManufacturedHoleTarget(
        front_points=s.target.front_points(),
        back_points=s.target.back_points(),
        back2front=s.target.back2front(),
    )
    return dataclasses.replace(
        s, target_made=perfect, back2front_cmm=s.target.back2front()
    ), rng


#: camera pose noise of the hand-eye test cells, rad and mm
HANDEYE_SIGMA_ROT, HANDEYE_SIGMA_TRANS = 1e-3, 0.2


def handeye_cell(seed=0, n=15, noise=True, **kw):
    """A simulated eye-in-hand cell of ``n`` poses (noise-free if ``noise`` is False)."""
    s = (HANDEYE_SIGMA_ROT, HANDEYE_SIGMA_TRANS) if noise else (0.0, 0.0)
    return simulate_cell(np.random.default_rng(seed), n, *s, **kw)


def assert_same_table(fresh, committed: Path, *, rtol: float | None = None) -> None:
    """``fresh`` (a DataFrame, or a CSV path) holds the same table as the committed CSV: the same
    columns and rows, text, counts and verdicts exactly, numbers within the tolerance of their
    unit plus ``rtol`` relative (:mod:`calstudy.io.tolerance`; by default ``TABLE_RTOL``, the
    tables keep 6 significant digits). A DataFrame goes through CSV first, as the writers store
    it."""
    from calstudy.io.tolerance import TABLE_RTOL, compare_tables

    def read(source):
        return pd.read_csv(source, keep_default_na=False, na_values=[""])

    if isinstance(fresh, pd.DataFrame):
        fresh = io.StringIO(fresh.to_csv(index=False))
    bad = compare_tables(read(fresh), read(committed), TABLE_RTOL if rtol is None else rtol)
    assert not bad, f"{Path(committed).name}: " + "; ".join(str(m) for m in bad)
