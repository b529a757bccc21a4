"""What the hybrid study starts from: the station, the production run and the published numbers.

Three files of ``data/hybrid/`` describe the paper's setup, each number a fact from the paper
(section given) or a documented assumption, each input with its provenance
(:mod:`calstudy.core.ledger`):

* ``station.toml``: the robot, the flexible and stationary sensors, the sphere, the hole target,
  the fixture and the workpiece frame (notebook 01; the station of notebook 02 too). Read by
  :func:`load_station` into a :class:`~calstudy.papers.hybrid.schema.StationFile`.
* ``production.toml``: the panel's 58 feature points, the part variation, the sensors' feature
  noise, the CMM, the drift and the protocol of section 4.3 (notebook 02). With the station it
  is the :class:`Scenario` of :func:`load_scenario`, whose :attr:`Scenario.features` are the
  panel's :class:`Features`.
* ``published.toml``: Table 1 and the other numbers of section 4.3 that notebook 02 compares
  with, read by :func:`load_published`.

Each file is validated on load against its schema (:mod:`calstudy.papers.hybrid.schema`: types,
ranges, required keys, cross-field rules) and the validated model is what the simulation reads;
a missing file, a malformed one or a missing key raise the same errors as in the other papers.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from functools import cached_property, reduce
from pathlib import Path

import numpy as np

from calstudy.core.errors import CalibrationError
from calstudy.core.schema import Schema, load_paper_file
from calstudy.estimators.workpiece import RPS_EQUATIONS
from calstudy.papers.hybrid.schema import ProductionFile, PublishedFile, StationFile

PAPER = "hybrid"
STATION_FILE = "station.toml"
PRODUCTION_FILE = "production.toml"
PUBLISHED_FILE = "published.toml"

AXES = ("x", "y", "z")
#: the two phases of the production protocol: the products of the offset, then the follow-up
PHASES = ("compensation", "follow-up")

#: the assumptions that the sensitivity sweep may move (the names of its ``parameter`` column),
#: with axis labels
SWEEP_LABELS = {
    "part_sigma_mm": "part variation sigma (mm)",
    "feature_sigma_mm": "sensor feature noise sigma (mm)",
    "repeatability_mm": "robot repeatability (+-mm, 3 sigma)",
    "drift_sigma_mm": "drift before follow-up, sigma (mm)",
}
#: each swept assumption's dotted key in :class:`Scenario`
SWEEP_KEYS = {
    "part_sigma_mm": "production.variation.part_sigma_mm",
    "feature_sigma_mm": "production.sensors.feature_sigma_mm",
    "repeatability_mm": "station.robot.repeatability_mm",
    "drift_sigma_mm": "production.drift.sigma_mm",
}


def load_station(
    path: str | Path | None = None, overrides: Mapping[str, object] | None = None
) -> StationFile:
    """The station description (default ``data/hybrid/station.toml``), validated.

    Parameters
    ----------
    path : str or Path, optional
        The file; default (None or ``""``) the paper's.
    overrides : mapping of str to object, optional
        Dotted keys of the file and their values (``{"sensor.sigma_point_mm": 0.02}``), applied
        before validation (:func:`calstudy.core.schema.apply_overrides`): a value outside its
        ledger range is refused as in the file.

    Returns
    -------
    StationFile
        The frozen, validated station.

    Raises
    ------
    FileNotFoundError
        If the file is missing (the message names it).
    CalibrationError
        If it is not TOML or breaks :class:`~calstudy.papers.hybrid.schema.StationFile`: a
        missing or unknown key, a value out of range (the message names file, key, value and
        range), a hand-eye matrix that is not rigid, collinear datums; or an override names no
        input.
    """
    return load_paper_file(
        PAPER, STATION_FILE, StationFile, "hybrid station description", path, overrides
    )


def load_production(
    path: str | Path | None = None, overrides: Mapping[str, object] | None = None
) -> ProductionFile:
    """The production description (default ``data/hybrid/production.toml``), validated against
    :class:`~calstudy.papers.hybrid.schema.ProductionFile` (parameters, returns and errors as
    :func:`load_station`)."""
    return load_paper_file(
        PAPER, PRODUCTION_FILE, ProductionFile, "hybrid production description", path, overrides
    )


def load_published(path: str | Path | None = None) -> PublishedFile:
    """The published numbers (default ``data/hybrid/published.toml``), checked against
    :class:`~calstudy.papers.hybrid.schema.PublishedFile` (shares that agree with their counts,
    ascending bin edges; errors as :func:`load_station`)."""
    return load_paper_file(
        PAPER, PUBLISHED_FILE, PublishedFile, "published numbers of the hybrid paper", path
    )


# ---------------------------------------------------------------------------------------------
# the feature points of the panel


@dataclass(frozen=True)
class Features:
    """The feature points of the panel, flexible ones first.

    Attributes
    ----------
    ids, kinds : tuple of str
        Point ids (unique) and what the feature is.
    sensor : (F,) int array
        0 for the flexible sensor, ``i`` for stationary sensor ``i`` (1-10).
    cad : (F, 3) array
        Nominal coordinates in the workpiece frame, mm.
    view : (F, 3) array
        Unit direction from the feature towards the flexible sensor (WF); unused for stationary.
    yaw : (F,) array
        Turn of the flexible sensor about its axis in the taught program, rad (0 for stationary).
    fixed : (F, 3) bool array
        Coordinates fixed by the 3-2-1 frame (A: y, z; B: x, y, z; C: z).
    """

    ids: tuple
    kinds: tuple
    sensor: np.ndarray
    cad: np.ndarray
    view: np.ndarray
    yaw: np.ndarray
    fixed: np.ndarray

    @property
    def flexible(self) -> np.ndarray:
        """Indices of the points measured by the flexible sensor."""
        return np.flatnonzero(self.sensor == 0)

    @property
    def stationary(self) -> np.ndarray:
        """Indices of the points measured by stationary sensors (in sensor order)."""
        idx = np.flatnonzero(self.sensor > 0)
        return idx[np.argsort(self.sensor[idx], kind="stable")]


def panel_features(production: ProductionFile, station: StationFile) -> Features:
    """The feature points of ``production`` (58 in the paper's file), flexible ones first;
    datums A, B, C (the first three stationary points) from ``station``.

    Parameters
    ----------
    production, station : ProductionFile, StationFile
        The validated files (:func:`load_production`, :func:`load_station`).

    Returns
    -------
    Features
        Ids, kinds, sensors, CAD coordinates (mm), view directions, yaws (rad) and the
        coordinates the 3-2-1 frame fixes.
    """
    flex = production.flexible.features
    stat = production.stationary_features
    stat_xyz = [list(v) for v in station.workpiece.datums] + list(stat.others_xyz_mm)
    view = np.array([f.view for f in flex] + [[0.0, 0.0, -1.0]] * len(stat_xyz), dtype=float)
    view /= np.linalg.norm(view, axis=1, keepdims=True)
    n_flex = len(flex)
    ids = tuple(f.id for f in flex) + tuple(stat.ids)
    fixed = np.zeros((len(ids), 3), dtype=bool)
    for datum, axis in RPS_EQUATIONS:
        fixed[n_flex + datum, axis] = True
    return Features(
        ids=ids,
        kinds=tuple(f.kind for f in flex) + tuple(stat.kinds),
        sensor=np.concatenate([np.zeros(n_flex, int), np.arange(1, len(stat_xyz) + 1)]),
        cad=np.array([f.xyz_mm for f in flex] + stat_xyz, dtype=float),
        view=view,
        yaw=np.deg2rad(np.array([f.yaw_deg for f in flex] + [0.0] * len(stat_xyz))),
        fixed=fixed,
    )


# ---------------------------------------------------------------------------------------------
# the scenario of notebook 02


class Scenario(Schema):
    """The hybrid study's inputs: the station (``station.toml``) and the production run
    (``production.toml``), each validated with its ledger. Its dotted keys begin with the file
    (``"production.variation.part_sigma_mm"``, ``"station.robot.repeatability_mm"``); a changed
    copy is :func:`calstudy.core.schema.with_inputs` (validated again)."""

    station: StationFile
    production: ProductionFile

    @cached_property
    def features(self) -> Features:
        """The panel's feature points (:func:`panel_features`)."""
        return panel_features(self.production, self.station)

    def swept(self, name: str) -> float:
        """The value of the swept assumption ``name`` (a key of :data:`SWEEP_KEYS`)."""
        return reduce(getattr, SWEEP_KEYS[name].split("."), self)


def load_scenario(
    path: str | Path | None = None,
    overrides: Mapping[str, object] | None = None,
    station_path: str | Path | None = None,
) -> Scenario:
    """The production scenario of ``path`` (default ``data/hybrid/production.toml``) on the
    station of ``station_path`` (default ``data/hybrid/station.toml``).

    Parameters
    ----------
    path, station_path : str or Path, optional
        The production and station files; default (None or ``""``) the paper's.
    overrides : mapping of str to object, optional
        Dotted keys beginning with the file, ``"production."`` or ``"station."``, and their
        values, applied to that file before validation (as :func:`load_station`).

    Returns
    -------
    Scenario
        Both files, validated and frozen.

    Raises
    ------
    FileNotFoundError, CalibrationError
        As :func:`load_station`; a CalibrationError also for an override key that begins with
        neither file.
    """
    parts: dict[str, dict[str, object]] = {"station": {}, "production": {}}
    for key, value in (overrides or {}).items():
        head, _, rest = str(key).partition(".")
        if head not in parts or not rest:
            raise CalibrationError(
                f"override {key!r}: a key of the hybrid scenario begins with 'station.' or "
                "'production.'"
            )
        parts[head][rest] = value
    return Scenario(
        station=load_station(station_path, parts["station"]),
        production=load_production(path, parts["production"]),
    )
