"""What the hybrid study starts from: the station, the production run and the published numbers.

Three files of ``data/hybrid/`` describe the paper's setup, each number a fact from the paper
(section given) or a documented assumption:

* ``station.toml``: the robot, the flexible and stationary sensors, the sphere, the hole target,
  the fixture and the workpiece frame (notebook 01; the station of notebook 02 too). Read by
  :func:`load_station`.
* ``production.toml``: the panel's 58 feature points, the part variation, the sensors' feature
  noise, the CMM, the drift and the protocol of section 4.3 (notebook 02). Read by
  :func:`load_production`; its assumptions are the :class:`Scenario` of :func:`load_scenario`,
  its feature points the :class:`Features` of :func:`load_features`.
* ``published.toml``: Table 1 and the other numbers of section 4.3 that notebook 02 compares
  with, read by :func:`load_published`.

Every file is read through :mod:`calstudy.core.config`, so a missing file, a malformed one or a
missing key raise the same errors as in the other papers; ``station.toml`` and
``production.toml`` (and ``published.toml``) are checked on load against the schemas of
:mod:`calstudy.papers.hybrid.schema` (types, ranges, required keys, cross-field rules).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from calstudy.core.config import require, scenario_file
from calstudy.core.errors import CalibrationError
from calstudy.core.schema import check_toml
from calstudy.estimators.workpiece import RPS_EQUATIONS
from calstudy.papers.hybrid.schema import ProductionFile, PublishedFile, StationFile

PAPER = "hybrid"
STATION_FILE = "station.toml"
PRODUCTION_FILE = "production.toml"
PUBLISHED_FILE = "published.toml"

AXES = ("x", "y", "z")
#: the two phases of the production protocol: the products of the offset, then the follow-up
PHASES = ("compensation", "follow-up")

#: the assumptions of :class:`Scenario` that the sensitivity sweep may move, with axis labels
SWEEP_LABELS = {
    "part_sigma_mm": "part variation sigma (mm)",
    "feature_sigma_mm": "sensor feature noise sigma (mm)",
    "repeatability_mm": "robot repeatability (+-mm, 3 sigma)",
    "drift_sigma_mm": "drift before follow-up, sigma (mm)",
}


def _load(name: str, what: str, path: str | Path | None, model) -> dict:
    """The TOML file ``path`` (default ``data/hybrid/<name>``) after checking it against
    ``model`` (:mod:`calstudy.papers.hybrid.schema`)."""
    return check_toml(scenario_file(PAPER, name, path), model, what)


def load_station(path: str | Path | None = None) -> dict:
    """The station description (default ``data/hybrid/station.toml``) as a dict.

    Raises
    ------
    FileNotFoundError
        If the file is missing (the message names it).
    CalibrationError
        If it is not TOML or breaks :class:`~calstudy.papers.hybrid.schema.StationFile`: a
        missing or unknown key, a value out of range (the message names file, key, value and
        range), a hand-eye matrix that is not rigid, collinear datums.
    """
    return _load(STATION_FILE, "hybrid station description", path, StationFile)


def load_production(path: str | Path | None = None) -> dict:
    """The production description (default ``data/hybrid/production.toml``) as a dict, checked
    against :class:`~calstudy.papers.hybrid.schema.ProductionFile` (errors as
    :func:`load_station`)."""
    return _load(PRODUCTION_FILE, "hybrid production description", path, ProductionFile)


# ---------------------------------------------------------------------------------------------
# the published numbers


@dataclass(frozen=True)
class Published:
    """The numbers of the paper's section 4.3 that the study compares with.

    Attributes
    ----------
    deviation_bins, correlation_bins : tuple of str
        The five bin labels of each half of Table 1.
    deviation_edges_mm : tuple of float
        Upper edges of the first four bins of |deviation| (mm), each bin closed on the right.
    correlation_edges : tuple of float
        Edges of the correlation bins, ascending, each bin closed on the right.
    deviation_counts, correlation_counts : tuple of int
        Counts of the 174 vectors per bin (Table 1).
    deviation_percent, correlation_percent : tuple of float
        The same as printed shares (%).
    within_0p3_percent, r_above_0p7_percent : float
        The headline shares (%): deviation within +-0.3 mm and correlation above 0.7.
    systematic_mm : (float, float)
        The published size of the deviations before compensation, "about 2-4 mm".
    """

    deviation_bins: tuple
    deviation_edges_mm: tuple
    deviation_counts: tuple
    deviation_percent: tuple
    correlation_bins: tuple
    correlation_edges: tuple
    correlation_counts: tuple
    correlation_percent: tuple
    within_0p3_percent: float
    r_above_0p7_percent: float
    systematic_mm: tuple


#: field of :class:`Published` -> key of ``published.toml``
_PUBLISHED_KEYS = {
    **{
        f"{half}_{what}": f"table1.{half}_{what}"
        for half in ("deviation", "correlation")
        for what in ("bins", "counts", "percent")
    },
    "deviation_edges_mm": "table1.deviation_edges_mm",
    "correlation_edges": "table1.correlation_edges",
    "within_0p3_percent": "table1.within_0p3_percent",
    "r_above_0p7_percent": "table1.r_above_0p7_percent",
    "systematic_mm": "systematic.range_mm",
}


def load_published(path: str | Path | None = None) -> Published:
    """The published numbers (default ``data/hybrid/published.toml``; read once per path),
    checked against :class:`~calstudy.papers.hybrid.schema.PublishedFile` (shares that agree
    with their counts, ascending bin edges; errors as :func:`load_station`)."""
    return _published(str(scenario_file(PAPER, PUBLISHED_FILE, path)))


@functools.cache
def _published(path: str) -> Published:
    table = check_toml(path, PublishedFile, "published numbers of the hybrid paper")

    values = {name: require(table, key, path) for name, key in _PUBLISHED_KEYS.items()}
    return Published(**{k: tuple(v) if isinstance(v, list) else v for k, v in values.items()})


# ---------------------------------------------------------------------------------------------
# the production assumptions


#: Most products a protocol count may ask for: every simulated product's readings are held in
#: memory at once, so the counts are bounded before anything is allocated (the paper's protocol
#: uses tens).
MAX_PRODUCTS = 10_000


@dataclass(frozen=True)
class Scenario:
    """The production assumptions (mm) and protocol (product counts) of one simulation.

    Raises
    ------
    CalibrationError
        On a noise level that is negative or not finite, a product count that is not an
        integer from 3 to :data:`MAX_PRODUCTS`, or ``n_compensation_max`` below ``n_before`` or
        ``n_compensation``.
    """

    part_sigma_mm: float
    feature_sigma_mm: float
    repeatability_mm: float
    drift_sigma_mm: float
    cmm_sigma_mm: float
    n_before: int
    n_compensation: int
    n_compensation_max: int
    n_follow_up: int

    def __post_init__(self) -> None:
        for name in ("part_sigma_mm", "feature_sigma_mm", "repeatability_mm", "drift_sigma_mm"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value >= 0):
                raise CalibrationError(f"{name} is {value!r}; expected a finite value >= 0")
        if not (np.isfinite(self.cmm_sigma_mm) and self.cmm_sigma_mm >= 0):
            raise CalibrationError(f"cmm_sigma_mm is {self.cmm_sigma_mm!r}; expected >= 0")
        for name in ("n_before", "n_compensation", "n_compensation_max", "n_follow_up"):
            value = getattr(self, name)
            if not (
                isinstance(value, int | np.integer | float)
                and not isinstance(value, bool)
                and np.isfinite(value)
                and float(value).is_integer()
                and value <= MAX_PRODUCTS
            ):
                raise CalibrationError(
                    f"{name} is {value!r}; expected a whole number of products from 3 to "
                    f"{MAX_PRODUCTS} (each product's readings are held in memory)"
                )
        for name in ("n_before", "n_compensation", "n_follow_up"):
            if int(getattr(self, name)) < 3:
                raise CalibrationError(
                    f"{name} is {getattr(self, name)}; at least 3 products are needed"
                )
        if self.n_compensation_max < max(self.n_before, self.n_compensation):
            raise CalibrationError(
                f"n_compensation_max {self.n_compensation_max} is below n_before "
                f"{self.n_before} or n_compensation {self.n_compensation}"
            )

    def with_(self, **changes) -> Scenario:
        """A copy with some fields changed (checked again)."""
        return replace(self, **changes)


#: field of :class:`Scenario` -> key of ``production.toml`` (the repeatability is the station's)
_SCENARIO_KEYS = {
    "part_sigma_mm": "variation.part_sigma_mm",
    "feature_sigma_mm": "sensors.feature_sigma_mm",
    "drift_sigma_mm": "drift.sigma_mm",
    "cmm_sigma_mm": "cmm.sigma_mm",
    "n_before": "protocol.n_before",
    "n_compensation": "protocol.n_compensation",
    "n_compensation_max": "protocol.n_compensation_max",
    "n_follow_up": "protocol.n_follow_up",
}


def load_scenario(
    path: str | Path | None = None, station_path: str | Path | None = None
) -> Scenario:
    """The production scenario of ``path`` (default ``data/hybrid/production.toml``) with the
    robot repeatability of ``station_path`` (default ``data/hybrid/station.toml``)."""
    source = scenario_file(PAPER, PRODUCTION_FILE, path)
    cfg = load_production(source)
    values = {name: require(cfg, key, source) for name, key in _SCENARIO_KEYS.items()}
    repeatability = load_station(station_path)["robot"]["repeatability_mm"]
    return Scenario(repeatability_mm=repeatability, **values)


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


def load_features(config: dict | None = None, station_config: dict | None = None) -> Features:
    """The 58 feature points of ``production.toml``; datums A, B, C from ``station.toml``.

    ``config`` and ``station_config`` are the loaded files (default: :func:`load_production`
    and :func:`load_station`).
    """
    cfg = load_production() if config is None else config
    scfg = load_station() if station_config is None else station_config
    flex = cfg["flexible"]["features"]
    stat = cfg["stationary_features"]
    w = scfg["workpiece"]
    datums = [w["datum_A_slot_mm"], w["datum_B_hole_mm"], w["datum_C_plane_mm"]]
    stat_xyz = datums + list(stat["others_xyz_mm"])
    if len(stat["ids"]) != len(stat_xyz) or len(stat["kinds"]) != len(stat_xyz):
        raise CalibrationError(
            f"stationary_features lists {len(stat['ids'])} ids, {len(stat['kinds'])} kinds and "
            f"{len(stat_xyz)} points (3 datums + others); they must match"
        )
    ids = tuple(f["id"] for f in flex) + tuple(stat["ids"])
    _check_ids(list(ids), PRODUCTION_FILE)
    view = np.array([f["view"] for f in flex] + [[0.0, 0.0, -1.0]] * len(stat_xyz), dtype=float)
    view /= np.linalg.norm(view, axis=1, keepdims=True)
    n_flex = len(flex)
    fixed = np.zeros((len(ids), 3), dtype=bool)
    for datum, axis in RPS_EQUATIONS:
        fixed[n_flex + datum, axis] = True
    return Features(
        ids=ids,
        kinds=tuple(f["kind"] for f in flex) + tuple(stat["kinds"]),
        sensor=np.concatenate([np.zeros(n_flex, int), np.arange(1, len(stat_xyz) + 1)]),
        cad=np.array([f["xyz_mm"] for f in flex] + stat_xyz, dtype=float),
        view=view,
        yaw=np.deg2rad(np.array([f["yaw_deg"] for f in flex] + [0.0] * len(stat_xyz))),
        fixed=fixed,
    )


def _check_ids(ids: list, where: str) -> None:
    seen, dup = set(), []
    for i in ids:
        if i in seen:
            dup.append(i)
        seen.add(i)
    if dup:
        raise CalibrationError(f"duplicated feature points in {where}: {sorted(set(dup))}")
