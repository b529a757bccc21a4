"""The hybrid station in production (hybrid paper, section 4.3): panels, CMM, offset compensation.

The calibrated station of :mod:`calstudy.papers.hybrid.station` measures a run of rear underbody
panels. Each
panel carries 58 feature points (``data/hybrid/production.toml``): 48 measured by the flexible
sensor, one taught robot pose each, and 10 by the stationary sensors, the first three of which
are the datums A (slot), B (hole) and C (plane) that fix the workpiece frame by the 3-2-1 rule. A
CMM measures the same panels. The paper then

1. looks at the deviations hybrid minus CMM of 10 panels before compensation (Fig. 6): systematic,
   a few millimetres, normal by the Lilliefors test;
2. learns one offset per feature coordinate from ``n`` products (Eq. 24) and adds it to later
   measurements (Eq. 25);
3. bins the compensated deviations and the hybrid-CMM correlation coefficients (Eq. 26) of the 174
   coordinates ("vectors", 58 points x 3 axes) over 30 later products (Table 1).

The analysis functions take measurement arrays ``(products, points, 3)`` (or the long tables of
:func:`measurements_from_frames`, so measured CSVs can be fed in); the simulation functions make
those arrays for a drawn station. Every deviation is hybrid minus CMM, in mm, in the workpiece
frame (WF).

Coordinates that the 3-2-1 rule fixes (A: y, z; B: x, y, z; C: z) are the same on every panel in
both systems, by the definition of the frame: their deviation is 0 and their correlation is
undefined. They are found by :func:`frame_fixed` and reported as such, never as NaN.
"""

from __future__ import annotations

import time
import tomllib
from dataclasses import dataclass, field, replace

import numpy as np
import pandas as pd

from calstudy.claims import verdict_vs_published
from calstudy.core import geometry as geo
from calstudy.core.errors import CalibrationError
from calstudy.core.paths import data_path
from calstudy.core.stats import percentile_interval
from calstudy.estimators.handeye import sphere_handeye
from calstudy.estimators.workpiece import RPS_EQUATIONS, check_datums
from calstudy.papers.hybrid.station import (
    HybridStation,
    load_config,
    log_progress,
    make_station,
    repeatability_joint_sigma,
    simulate_sphere_measurements,
    stationary_trial,
    trial_generators,
)

AXES = ("x", "y", "z")
PHASES = ("compensation", "follow-up")
MEASUREMENT_COLUMNS = ("product", "phase", "point_id", "x_mm", "y_mm", "z_mm")

#: Table 1 of the paper: bins of |deviation| (mm) and of the correlation coefficient, counts of 174
DEVIATION_BINS = ("[-0.1, 0.1]", "0.1-0.2", "0.2-0.3", "0.3-0.5", "beyond 0.5")
DEVIATION_EDGES = (0.1, 0.2, 0.3, 0.5)
PUBLISHED_DEVIATION_COUNTS = (37, 82, 49, 6, 0)
PUBLISHED_DEVIATION_PERCENT = (21.26, 47.13, 28.16, 3.45, 0.0)
CORRELATION_BINS = ("> 0.9", "0.8-0.9", "0.7-0.8", "0.6-0.7", "<= 0.6")
CORRELATION_EDGES = (0.6, 0.7, 0.8, 0.9)
PUBLISHED_CORRELATION_COUNTS = (28, 58, 63, 10, 15)
PUBLISHED_CORRELATION_PERCENT = (16.09, 33.33, 36.21, 5.74, 8.62)
PUBLISHED_WITHIN_0P3 = 96.55
PUBLISHED_R_ABOVE_0P7 = 85.64
PUBLISHED_SYSTEMATIC_MM = (2.0, 4.0)

#: swept assumptions: scenario field, axis label
SWEEP_LABELS = {
    "part_sigma_mm": "part variation sigma (mm)",
    "feature_sigma_mm": "sensor feature noise sigma (mm)",
    "repeatability_mm": "robot repeatability (+-mm, 3 sigma)",
    "drift_sigma_mm": "drift before follow-up, sigma (mm)",
}
#: axis label of the sweep of the robot's manufacturing errors (:func:`robot_error_sweep`)
ROBOT_ERROR_LABEL = "factor on the robot's kinematic tolerances"


def load_production_config() -> dict:
    """The production description ``data/hybrid/production.toml`` as a dict."""
    with open(data_path("hybrid", "production.toml"), "rb") as handle:
        return tomllib.load(handle)


# ---------------------------------------------------------------------------------------------
# features and scenario


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
    """The 58 feature points of ``production.toml``; datums A, B, C from ``station.toml``."""
    cfg = load_production_config() if config is None else config
    scfg = load_config() if station_config is None else station_config
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
    _check_ids(list(ids), "production.toml")
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


def features_table(features: Features) -> pd.DataFrame:
    """The features as a table: id, kind, sensor, CAD x, y, z (mm), coordinates fixed by the
    frame."""
    return pd.DataFrame(
        {
            "point_id": features.ids,
            "kind": features.kinds,
            "sensor": ["flexible" if s == 0 else f"stationary {s}" for s in features.sensor],
            "x_mm": features.cad[:, 0],
            "y_mm": features.cad[:, 1],
            "z_mm": features.cad[:, 2],
            "fixed_by_frame": [
                ", ".join(a for a, f in zip(AXES, row, strict=True) if f) for row in features.fixed
            ],
        }
    )


@dataclass(frozen=True)
class Scenario:
    """The production assumptions (mm) and protocol (product counts) of one simulation."""

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


def default_scenario() -> Scenario:
    """The scenario of ``production.toml`` and the repeatability of ``station.toml``."""
    cfg = load_production_config()
    p = cfg["protocol"]
    return Scenario(
        part_sigma_mm=cfg["variation"]["part_sigma_mm"],
        feature_sigma_mm=cfg["sensors"]["feature_sigma_mm"],
        repeatability_mm=load_config()["robot"]["repeatability_mm"],
        drift_sigma_mm=cfg["drift"]["sigma_mm"],
        cmm_sigma_mm=cfg["cmm"]["sigma_mm"],
        n_before=p["n_before"],
        n_compensation=p["n_compensation"],
        n_compensation_max=p["n_compensation_max"],
        n_follow_up=p["n_follow_up"],
    )


# ---------------------------------------------------------------------------------------------
# the workpiece frame of many panels at once


def rps_frame_batch(datums_base, datums_work, initial, tol: float = 1e-9, max_iter: int = 30):
    """``base2work (N, 4, 4)`` of N panels by the 3-2-1 rule (Eq. 3), R on SO(3), vectorised.

    Solves the six equations of Eq. 3 exactly for every panel at once by Newton steps
    on ``(T, rotation vector)`` (the same solution as
    :func:`calstudy.estimators.workpiece.rps_frame_so3`).

    Parameters
    ----------
    datums_base : (N, 3, 3) array
        Measured datums A, B, C of each panel in the base frame, mm.
    datums_work : (3, 3) array
        The datums in the workpiece frame (CAD), mm.
    initial : (4, 4) array
        Starting ``base2work`` (the nominal fixture pose).
    tol : float
        Largest residual (mm) accepted.
    max_iter : int
        Newton steps allowed.

    Raises
    ------
    CalibrationError
        On bad shapes, degenerate CAD datums, a singular system or no convergence.
    """
    p = np.asarray(datums_base, dtype=float)
    if p.ndim != 3 or p.shape[1:] != (3, 3):
        raise CalibrationError(f"datums_base has shape {p.shape}; expected (N, 3, 3)")
    geo.check_finite("datums_base", p)
    _, w = check_datums(p[0], datums_work)
    init = geo.check_transform("initial base2work", initial)
    n = p.shape[0]
    di = np.array([d for d, _ in RPS_EQUATIONS])
    ai = np.array([a for _, a in RPS_EQUATIONS])
    rot = np.broadcast_to(init[:3, :3], (n, 3, 3)).copy()
    trans = np.broadcast_to(init[:3, 3], (n, 3)).copy()
    jac = np.zeros((n, 6, 6))
    jac[:, np.arange(6), ai] = 1.0
    for _ in range(max_iter):
        rp = np.einsum("nij,nkj->nki", rot, p)  # R p_k, (n, 3 datums, 3)
        res = (rp + trans[:, None, :])[:, di, ai] - w[di, ai]
        if np.abs(res).max() < tol:
            break
        # left perturbation R <- exp(w) R moves R p by w x (R p) = -[R p]x w
        v = rp[:, di, :]
        jac[:, :, 3:] = -geo.skew(v)[:, np.arange(6), ai, :]
        try:
            step = np.linalg.solve(jac, -res[..., None])[..., 0]
        except np.linalg.LinAlgError as exc:
            raise CalibrationError(f"3-2-1 system is singular for some panel: {exc}") from exc
        trans += step[:, :3]
        rot = geo.rotvec_to_matrix(step[:, 3:]) @ rot
    else:
        raise CalibrationError(
            f"3-2-1 frame did not converge in {max_iter} steps (largest residual "
            f"{np.abs(res).max():.3g} mm)"
        )
    return geo.make_transform(rot, trans)


# ---------------------------------------------------------------------------------------------
# the station in production


_PROGRAM_CACHE: dict = {}


def sensor_poses(station: HybridStation, features: Features) -> np.ndarray:
    """Nominal ``sensor2base (F_flex, 4, 4)`` of the taught program: each flexible feature on the
    sensor axis at the stand-off, the sensor looking along ``-view`` turned by ``yaw``."""
    idx = features.flexible
    work2base = geo.invert(station.base2work_nominal)
    z = -features.view[idx] @ work2base[:3, :3].T
    ref = np.where(np.abs(z[:, 2:3]) < 0.99, np.array([0.0, 0.0, 1.0]), np.array([1.0, 0.0, 0.0]))
    # x axis horizontal (or along base x when looking straight down or up), then the taught yaw
    x = np.where(
        np.abs(z[:, 2:3]) < 0.99, np.cross(ref, z), np.array([[1.0, 0.0, 0.0]]) * np.ones_like(z)
    )
    x /= np.linalg.norm(x, axis=1, keepdims=True)
    y = np.cross(z, x)
    rot = np.stack([x, y, z], axis=2) @ geo.rotvec_to_matrix(
        np.column_stack([np.zeros((len(idx), 2)), features.yaw[idx]])
    )
    p_base = geo.apply(work2base, features.cad[idx])
    return geo.make_transform(rot, p_base - station.standoff * rot[:, :, 2])


def teach_program(station: HybridStation, features: Features) -> np.ndarray:
    """Joint angles ``(F_flex, 6)`` of the robot program, computed on the nominal robot.

    The program is written offline from CAD: nominal robot, the design hand-eye, the nominal
    fixture pose. It depends on no random draw, so it is computed once and cached.
    """
    key = (
        features.cad.tobytes(),
        features.view.tobytes(),
        features.yaw.tobytes(),
        station.sensor2flange_true.tobytes(),
        station.base2work_nominal.tobytes(),
        station.nominal.parameters().tobytes(),
    )
    if key not in _PROGRAM_CACHE:
        poses = sensor_poses(station, features) @ geo.invert(station.sensor2flange_true)
        q = []
        for pid, pose in zip(np.array(features.ids)[features.flexible], poses, strict=True):
            try:
                q.append(station.solve_ik(station.nominal, pose))
            except CalibrationError as exc:
                raise CalibrationError(f"feature {pid} is out of reach: {exc}") from exc
        _PROGRAM_CACHE[key] = np.array(q)
    return _PROGRAM_CACHE[key]


@dataclass
class ProductionStation:
    """A calibrated station ready to measure panels.

    ``sensor2flange`` and ``statcam2base`` are the calibrations the station computes with;
    the truth is in ``station``.
    """

    station: HybridStation
    features: Features
    program: np.ndarray
    sensor2flange: np.ndarray
    statcam2base: np.ndarray
    _joint_sigmas: dict = field(default_factory=dict, repr=False)

    def joint_sigma(self, repeatability_mm: float) -> float:
        """Joint noise (rad) for a repeatability of +-``repeatability_mm`` (3 sigma)."""
        if repeatability_mm not in self._joint_sigmas:
            self._joint_sigmas[repeatability_mm] = repeatability_joint_sigma(
                self.station, repeatability_mm / 3.0
            )
        return self._joint_sigmas[repeatability_mm]

    def reported_sensor2base(self) -> np.ndarray:
        """``sensor2base`` the station computes with at each program pose: nominal FK, calibrated
        hand-eye."""
        return self.station.nominal.fk_many(self.program) @ self.sensor2flange


def calibrated_station(
    rng: np.random.Generator, robot_errors: bool = True, robot_error_scale: float = 1.0
) -> ProductionStation:
    """Draw a station and calibrate it as notebook 01 does (sphere hand-eye, homography chain).

    ``robot_error_scale`` multiplies the robot's kinematic tolerances (see
    :func:`calstudy.papers.hybrid.station.make_station`).
    """
    station = make_station(rng, robot_errors=robot_errors, robot_error_scale=robot_error_scale)
    return calibrate(station, rng)


def calibrate(st: HybridStation, rng: np.random.Generator) -> ProductionStation:
    """Calibrate a drawn station by the paper's methods: the flexible sensor from the sphere
    (4 translations, 6 pose changes), the stationary sensors by the homography chain (Eq. 23)."""
    features = load_features(station_config=st.config)
    meas, _ = simulate_sphere_measurements(st, 4, 6, rng)
    s2f = sphere_handeye(*meas.select("translation"), *meas.select("rotation")).value
    rows = stationary_trial(st, s2f, rng)
    cams = np.array([r["estimate"] for r in rows if r["variant"] == "homography"])
    return ProductionStation(st, features, teach_program(st, features), s2f, cams)


def _transform_points(t: np.ndarray, p: np.ndarray) -> np.ndarray:
    """``t (..., 4, 4)`` applied to ``p (..., 3)`` (broadcast)."""
    return np.einsum("...ij,...j->...i", t[..., :3, :3], p) + t[..., :3, 3]


def simulate_products(
    ps: ProductionStation,
    scenario: Scenario,
    n_products: int,
    rng: np.random.Generator,
    drift=None,
) -> tuple[np.ndarray, np.ndarray]:
    """Measure ``n_products`` new panels on the station and on the CMM.

    Per panel: feature coordinates ``CAD + N(0, part_sigma)`` (fixed coordinates excepted), a
    clamping pose on the fixture (``station.toml``); the flexible sensor at each program pose of
    the *true* robot (joint noise of the repeatability), the stationary sensors where they truly
    are, each reading with ``feature_sigma`` noise (datums: ``datum_sigma``); the station maps
    readings to the base frame with the nominal robot and its calibrations, builds the 3-2-1 frame
    from its datum readings and reports WF coordinates, plus ``drift`` ``(F, 3)`` if given. The
    CMM reports the true WF coordinates with ``cmm_sigma`` noise.

    Returns
    -------
    hybrid, cmm : (n_products, F, 3) arrays
        WF coordinates, mm.
    """
    st, f = ps.station, ps.features
    n, nf = int(n_products), len(f.ids)
    if n < 1:
        raise CalibrationError(f"n_products is {n_products}; at least 1 panel needed")
    dev = rng.normal(0.0, scenario.part_sigma_mm, (n, nf, 3))
    dev[:, f.fixed] = 0.0
    truth_work = f.cad + dev
    wcfg = st.config["workpiece"]
    work2base = geo.perturb(
        np.broadcast_to(geo.invert(st.base2work_nominal), (n, 4, 4)),
        np.deg2rad(wcfg["placement_sigma_deg"]),
        wcfg["placement_sigma_mm"],
        rng,
    )
    truth_base = _transform_points(work2base[:, None], truth_work)
    measured_base = np.empty_like(truth_base)
    # flexible sensor: true robot at the program joints (plus repeatability), nominal computation
    fl = f.flexible
    sigma_q = ps.joint_sigma(scenario.repeatability_mm)
    q = ps.program[None] + rng.normal(0.0, sigma_q, (n,) + ps.program.shape)
    actual = st.true.fk_many(q.reshape(-1, q.shape[-1])).reshape(n, len(fl), 4, 4)
    sensor2base = actual @ st.sensor2flange_true
    in_sensor = _transform_points(geo.invert(sensor2base), truth_base[:, fl])
    in_sensor += rng.normal(0.0, scenario.feature_sigma_mm, in_sensor.shape)
    measured_base[:, fl] = _transform_points(ps.reported_sensor2base()[None], in_sensor)
    # stationary sensors: true pose for the reading, calibrated pose for the computation
    sn = f.stationary
    cams = f.sensor[sn] - 1
    in_cam = _transform_points(geo.invert(st.statcam2base_true[cams])[None], truth_base[:, sn])
    sigma = np.where(np.isin(cams, (0, 1, 2)), st.datum_sigma, scenario.feature_sigma_mm)
    in_cam += rng.normal(0.0, 1.0, in_cam.shape) * sigma[None, :, None]
    measured_base[:, sn] = _transform_points(ps.statcam2base[cams][None], in_cam)
    base2work = rps_frame_batch(measured_base[:, sn[:3]], st.datums_work, st.base2work_nominal)
    hybrid = _transform_points(base2work[:, None], measured_base)
    # the frame is defined by these coordinates: exactly CAD in both systems
    hybrid[:, f.fixed] = f.cad[f.fixed]
    if drift is not None:
        hybrid += np.where(f.fixed, 0.0, np.asarray(drift, dtype=float))
    cmm = truth_work + rng.normal(0.0, scenario.cmm_sigma_mm, truth_work.shape)
    cmm[:, f.fixed] = f.cad[f.fixed]
    return hybrid, cmm


def simulate_run(ps: ProductionStation, scenario: Scenario, rng: np.random.Generator) -> dict:
    """The paper's protocol on one station: ``n_compensation_max`` products after installation
    (the first ``n_before`` are the ones of Fig. 6), then, after a drift of ``drift_sigma`` per
    coordinate, ``n_follow_up`` products. Returns ``{phase: (hybrid, cmm)}`` for :data:`PHASES`."""
    comp = simulate_products(ps, scenario, scenario.n_compensation_max, rng)
    drift = rng.normal(0.0, scenario.drift_sigma_mm, (len(ps.features.ids), 3))
    follow = simulate_products(ps, scenario, scenario.n_follow_up, rng, drift=drift)
    return {"compensation": comp, "follow-up": follow}


# ---------------------------------------------------------------------------------------------
# measurement tables (the user's CSVs or the simulation)


def _check_ids(ids: list, where: str) -> None:
    seen, dup = set(), []
    for i in ids:
        if i in seen:
            dup.append(i)
        seen.add(i)
    if dup:
        raise CalibrationError(f"duplicated feature points in {where}: {sorted(set(dup))}")


def measurements_frame(ids, run: dict, which: int) -> pd.DataFrame:
    """A long table (:data:`MEASUREMENT_COLUMNS`) of the hybrid (``which=0``) or CMM (1) readings
    of a run ``{phase: (hybrid, cmm)}``; products are numbered from 1 across phases."""
    frames, start = [], 1
    for phase in PHASES:
        if phase not in run:
            continue
        a = run[phase][which]
        n, nf = a.shape[:2]
        frames.append(
            pd.DataFrame(
                {
                    "product": np.repeat(np.arange(start, start + n), nf),
                    "phase": phase,
                    "point_id": np.tile(np.asarray(ids, dtype=object), n),
                    "x_mm": a[..., 0].ravel(),
                    "y_mm": a[..., 1].ravel(),
                    "z_mm": a[..., 2].ravel(),
                }
            )
        )
        start += n
    return pd.concat(frames, ignore_index=True)


def _table_to_array(df: pd.DataFrame, name: str):
    """``(ids, products, phases, array (P, F, 3))`` of one long table, after checking it."""
    missing = [c for c in MEASUREMENT_COLUMNS if c not in df.columns]
    if missing:
        raise CalibrationError(
            f"the {name} table lacks columns {missing}; needs {MEASUREMENT_COLUMNS}"
        )
    if len(df) == 0:
        raise CalibrationError(f"the {name} table is empty (0 rows)")
    df = df.assign(point_id=df["point_id"].astype(str))
    dup = df[df.duplicated(["product", "point_id"], keep=False)]
    if len(dup):
        first = dup.iloc[0]
        same = (dup["product"] == first["product"]) & (dup["point_id"] == first["point_id"])
        raise CalibrationError(
            f"duplicated feature point in the {name} table: point {first['point_id']} appears "
            f"{int(same.sum())} times in product {first['product']} ({len(dup)} duplicated "
            "rows in all)"
        )
    bad_phase = sorted(set(df["phase"]) - set(PHASES))
    if bad_phase:
        raise CalibrationError(f"the {name} table has phases {bad_phase}; use {PHASES}")
    ids = list(dict.fromkeys(df["point_id"]))
    products = list(dict.fromkeys(df["product"]))
    for p, sub in df.groupby("product", sort=False):
        lacking = [i for i in ids if i not in set(sub["point_id"])]
        if lacking:
            raise CalibrationError(
                f"product {p} of the {name} table lacks {len(lacking)} feature point(s): "
                f"{lacking[:10]}"
            )
        if sub["phase"].nunique() != 1:
            raise CalibrationError(f"product {p} of the {name} table has more than one phase")
    wide = df.set_index(["product", "point_id"]).loc[pd.MultiIndex.from_product([products, ids])]
    values = wide[["x_mm", "y_mm", "z_mm"]].to_numpy(float).reshape(len(products), len(ids), 3)
    if not np.all(np.isfinite(values)):
        raise CalibrationError(
            f"the {name} table holds {int((~np.isfinite(values)).sum())} non-finite coordinates"
        )
    phases = df.drop_duplicates("product").set_index("product").loc[products, "phase"].tolist()
    return ids, products, phases, values


def measurements_from_frames(hybrid: pd.DataFrame, cmm: pd.DataFrame):
    """Pair a hybrid and a CMM table (:data:`MEASUREMENT_COLUMNS`): ``(ids, run)``.

    ``run`` is ``{phase: (hybrid (P, F, 3), cmm (P, F, 3))}`` with the points in the order of
    ``ids``, as :func:`simulate_run` returns it.

    Raises
    ------
    CalibrationError
        On missing columns, duplicated or missing feature points, point ids or products that
        differ between the two tables, unknown phases or non-finite coordinates.
    """
    ids_h, prod_h, ph_h, h = _table_to_array(hybrid, "hybrid")
    ids_c, prod_c, ph_c, c = _table_to_array(cmm, "CMM")
    if set(ids_h) != set(ids_c):
        raise CalibrationError(
            "point ids differ between the hybrid and CMM tables: only in hybrid "
            f"{sorted(set(ids_h) - set(ids_c))[:10]}, only in CMM "
            f"{sorted(set(ids_c) - set(ids_h))[:10]}"
        )
    if set(prod_h) != set(prod_c):
        raise CalibrationError(
            f"products differ between the hybrid and CMM tables: only in hybrid "
            f"{sorted(set(prod_h) - set(prod_c))[:10]}, only in CMM "
            f"{sorted(set(prod_c) - set(prod_h))[:10]}"
        )
    order_p = [prod_c.index(p) for p in prod_h]
    order_f = [ids_c.index(i) for i in ids_h]
    c = c[order_p][:, order_f]
    ph_c = [ph_c[k] for k in order_p]
    if ph_h != ph_c:
        raise CalibrationError("a product has different phases in the hybrid and CMM tables")
    run = {}
    for phase in PHASES:
        sel = np.array([p == phase for p in ph_h])
        if sel.any():
            run[phase] = (h[sel], c[sel])
    return ids_h, run


def read_measurements(hybrid_csv: str, cmm_csv: str):
    """:func:`measurements_from_frames` on two CSV files."""
    return measurements_from_frames(pd.read_csv(hybrid_csv), pd.read_csv(cmm_csv))


# ---------------------------------------------------------------------------------------------
# statistics of the paper (section 4.3)


def _as_products(name: str, a, minimum: int, what: str) -> np.ndarray:
    a = np.asarray(a, dtype=float)
    if a.ndim == 0 or a.shape[0] < minimum:
        n = 0 if a.ndim == 0 else a.shape[0]
        raise CalibrationError(f"{what} needs at least {minimum} products; {name} holds {n}")
    geo.check_finite(name, a)
    return a


def _constant(a: np.ndarray) -> np.ndarray:
    """Which series (axis 0) are constant (range below 1e-12 of their size)."""
    return np.ptp(a, axis=0) <= 1e-12 * np.maximum(1.0, np.abs(a).max(axis=0))


def lilliefors_test(samples) -> tuple[float, float]:
    """Lilliefors test for normality (statsmodels, table p-values): ``(statistic, p_value)``.

    Raises
    ------
    CalibrationError
        With fewer than 4 samples (statsmodels' minimum; the paper uses 10 panels), non-finite
        values, or constant data (the normal fit has zero spread).
    """
    from statsmodels.stats.diagnostic import lilliefors

    x = _as_products("samples", samples, 4, "a Lilliefors test")
    if x.ndim != 1:
        raise CalibrationError(f"samples has shape {x.shape}; expected (n,)")
    if _constant(x):
        raise CalibrationError(
            f"all {x.size} samples equal {x[0]:.6g}: a normal fit and the Lilliefors test are "
            "undefined for constant data"
        )
    stat, p = lilliefors(x, dist="norm", pvalmethod="table")
    return float(stat), float(p)


def offsets(hybrid, cmm) -> np.ndarray:
    """The offset of each coordinate from ``n`` products (Eq. 24): ``mean(cmm - hybrid)``.

    Parameters
    ----------
    hybrid, cmm : (n, F, 3) arrays
        Readings of the same products and points, mm.

    Raises
    ------
    CalibrationError
        With fewer than 3 products, different shapes or non-finite values.
    """
    h = _as_products("hybrid", hybrid, 3, "an offset estimate")
    c = _as_products("cmm", cmm, 3, "an offset estimate")
    if h.shape != c.shape:
        raise CalibrationError(f"hybrid has shape {h.shape} and cmm {c.shape}; they must match")
    return np.mean(c - h, axis=0)


def compensate(hybrid, offset) -> np.ndarray:
    """Compensated readings (Eq. 25): ``hybrid + offset``, the offset broadcast over products."""
    h = np.asarray(hybrid, dtype=float)
    o = np.asarray(offset, dtype=float)
    if h.shape[1:] != o.shape:
        raise CalibrationError(f"offset has shape {o.shape}; readings {h.shape} need {h.shape[1:]}")
    return h + o


def correlations(hybrid, cmm) -> np.ndarray:
    """Pearson correlation of hybrid and CMM readings of each coordinate over products (Eq. 26).

    Parameters
    ----------
    hybrid, cmm : (n, ...) arrays
        Readings, products on axis 0.

    Returns
    -------
    numpy.ndarray, shape (...)
        ``r`` per coordinate.

    Raises
    ------
    CalibrationError
        With fewer than 3 products, different shapes, or a constant series (``r`` is undefined;
        the message names the coordinates).
    """
    h = _as_products("hybrid", hybrid, 3, "a correlation coefficient")
    c = _as_products("cmm", cmm, 3, "a correlation coefficient")
    if h.shape != c.shape:
        raise CalibrationError(f"hybrid has shape {h.shape} and cmm {c.shape}; they must match")
    flat = _constant(h) | _constant(c)
    if np.any(flat):
        where = [tuple(int(i) for i in w) for w in np.argwhere(np.atleast_1d(flat))[:5]]
        raise CalibrationError(
            f"{int(flat.sum())} coordinate(s) are constant over the {h.shape[0]} products (first "
            f"at index {where}): the correlation coefficient is undefined there"
        )
    hc, cc = h - h.mean(axis=0), c - c.mean(axis=0)
    return np.sum(hc * cc, axis=0) / np.sqrt(np.sum(hc**2, axis=0) * np.sum(cc**2, axis=0))


def frame_fixed(hybrid, cmm) -> np.ndarray:
    """Coordinates ``(F, 3)`` fixed by the workpiece frame: constant and equal in both systems."""
    h, c = np.asarray(hybrid, dtype=float), np.asarray(cmm, dtype=float)
    return _constant(h) & _constant(c) & np.all(h == c, axis=0)


def deviation_bins(deviation) -> np.ndarray:
    """Counts ``(..., 5)`` of |deviation| (mm, last axis = coordinates) in Table 1's bins:
    <= 0.1, (0.1, 0.2], (0.2, 0.3], (0.3, 0.5], > 0.5."""
    d = np.abs(np.asarray(deviation, dtype=float))
    idx = np.digitize(d, DEVIATION_EDGES, right=True)
    return (idx[..., None] == np.arange(5)).sum(axis=-2)


def correlation_bins(r) -> np.ndarray:
    """Counts ``(..., 5)`` of correlation coefficients in Table 1's bins:
    > 0.9, (0.8, 0.9], (0.7, 0.8], (0.6, 0.7], <= 0.6."""
    idx = 4 - np.digitize(np.asarray(r, dtype=float), CORRELATION_EDGES, right=True)
    return (idx[..., None] == np.arange(5)).sum(axis=-2)


def analyse_run(run: dict, n_compensation: int) -> dict:
    """Table 1 of one run ``{phase: (hybrid, cmm)}`` with the offset from the first
    ``n_compensation`` products.

    Returns a dict: ``deviation`` (F, 3) mean compensated deviation over the follow-up,
    ``deviation_uncompensated`` (F, 3), ``r`` (F, 3) with NaN at the coordinates fixed by the
    frame, ``fixed`` (F, 3), ``deviation_counts`` (5,), ``correlation_counts`` (5,),
    ``n_vectors``, ``n_fixed``, and the shares (%) ``within_0p3``, ``beyond_0p5``,
    ``within_0p3_uncompensated``, ``single_within_0p3`` (all single readings) and ``r_above_0p7``
    (of the coordinates where r is defined).
    """
    comp_h, comp_c = run["compensation"]
    fu_h, fu_c = run["follow-up"]
    if n_compensation > comp_h.shape[0]:
        raise CalibrationError(
            f"n_compensation is {n_compensation} but only {comp_h.shape[0]} compensation "
            "products were measured"
        )
    off = offsets(comp_h[:n_compensation], comp_c[:n_compensation])
    comp = compensate(fu_h, off)
    single = comp - fu_c
    dev = single.mean(axis=0)
    dev_raw = (fu_h - fu_c).mean(axis=0)
    fixed = frame_fixed(np.concatenate([comp_h, fu_h]), np.concatenate([comp_c, fu_c]))
    r = np.full(dev.shape, np.nan)
    r[~fixed] = correlations(fu_h[:, ~fixed], fu_c[:, ~fixed])
    n_vec = dev.size
    counts_r = correlation_bins(r[~fixed])
    return {
        "deviation": dev,
        "deviation_uncompensated": dev_raw,
        "r": r,
        "fixed": fixed,
        "deviation_counts": deviation_bins(dev.ravel()),
        "correlation_counts": counts_r,
        "n_vectors": n_vec,
        "n_fixed": int(fixed.sum()),
        "within_0p3": 100.0 * np.mean(np.abs(dev) <= 0.3),
        "beyond_0p5": 100.0 * np.mean(np.abs(dev) > 0.5),
        "within_0p3_uncompensated": 100.0 * np.mean(np.abs(dev_raw) <= 0.3),
        "single_within_0p3": 100.0 * np.mean(np.abs(single) <= 0.3),
        "r_above_0p7": 100.0 * counts_r[:3].sum() / max(1, counts_r.sum()),
    }


def before_compensation(run: dict, n_before: int) -> dict:
    """Deviations of the first ``n_before`` products before compensation (Fig. 6).

    Returns ``deviations`` (n, F, 3), ``mean`` and ``std`` (F, 3), ``fixed`` (F, 3), and per
    coordinate not fixed by the frame the Lilliefors statistic and p-value and the p-value of a
    one-sample t-test of a zero mean (NaN at fixed coordinates).
    """
    from scipy.stats import ttest_1samp

    h, c = run["compensation"]
    h, c = h[:n_before], c[:n_before]
    _as_products("hybrid", h, 4, "the before-compensation analysis")
    d = h - c
    fixed = frame_fixed(h, c)
    stat = np.full(d.shape[1:], np.nan)
    p_lf = np.full(d.shape[1:], np.nan)
    for j, k in np.argwhere(~fixed):
        stat[j, k], p_lf[j, k] = lilliefors_test(d[:, j, k])
    p_t = np.full(d.shape[1:], np.nan)
    p_t[~fixed] = ttest_1samp(d[:, ~fixed], 0.0, axis=0).pvalue
    return {
        "deviations": d,
        "mean": d.mean(axis=0),
        "std": d.std(axis=0, ddof=1),
        "fixed": fixed,
        "lilliefors_stat": stat,
        "lilliefors_p": p_lf,
        "t_test_p": p_t,
    }


def before_table(ids, before: dict, level: float = 0.05) -> pd.DataFrame:
    """Per coordinate: mean and std of the deviation (mm), the Lilliefors statistic and p-value,
    whether normality is rejected at ``level``, the t-test p-value of a zero mean."""
    n_f = len(ids)
    fixed = before["fixed"].ravel()
    p = before["lilliefors_p"].ravel()
    return pd.DataFrame(
        {
            "point_id": np.repeat(np.asarray(ids, dtype=object), 3),
            "axis": np.tile(AXES, n_f),
            "mean_mm": before["mean"].ravel(),
            "std_mm": before["std"].ravel(),
            "lilliefors_stat": before["lilliefors_stat"].ravel(),
            "lilliefors_p": p,
            "normality": np.where(
                fixed, "fixed by the frame", np.where(p < level, "rejected", "not rejected")
            ),
            "mean_zero_p": before["t_test_p"].ravel(),
        }
    )


# ---------------------------------------------------------------------------------------------
# Monte Carlo


def trial_summary(run: dict, scenario: Scenario, n_values) -> tuple[dict, list[dict]]:
    """The systematic-error figures and the Table 1 figures (one row per ``n``) of one run."""
    before = before_compensation(run, scenario.n_before)
    free = ~before["fixed"]
    norms = np.linalg.norm(before["mean"], axis=1)
    system = {
        "systematic_median_mm": float(np.median(norms)),
        "systematic_max_mm": float(norms.max()),
        "scatter_median_mm": float(np.median(before["std"][free])),
        "lilliefors_not_rejected": 100.0 * float(np.mean(before["lilliefors_p"][free] >= 0.05)),
        "mean_nonzero": 100.0 * float(np.mean(before["t_test_p"][free] < 0.05)),
    }
    rows = []
    for n in n_values:
        a = analyse_run(run, int(n))
        row = {"n_compensation": int(n)}
        row |= {k: a[k] for k in ("within_0p3", "beyond_0p5", "within_0p3_uncompensated")}
        row |= {k: a[k] for k in ("single_within_0p3", "r_above_0p7", "n_vectors", "n_fixed")}
        row |= {f"deviation_bin{k}": int(v) for k, v in enumerate(a["deviation_counts"])}
        row |= {f"correlation_bin{k}": int(v) for k, v in enumerate(a["correlation_counts"])}
        rows.append(row)
    return system, rows


def production_monte_carlo(
    seed: int,
    n_trials: int,
    scenario: Scenario,
    n_values,
    stream: int = 0,
    progress: bool = False,
):
    """Run the paper's protocol on ``n_trials`` drawn and calibrated stations.

    Returns ``(systematic, table1, stations, first_run)``: one row per trial of the
    before-compensation figures; one row per trial and ``n`` of the Table 1 figures; the
    calibrated stations (for the sensitivity sweep); the run of trial 0.
    """
    start = time.perf_counter()
    n_values = sorted({int(n) for n in n_values} | {scenario.n_compensation})
    if max(n_values) > scenario.n_compensation_max:
        raise CalibrationError(
            f"n values up to {max(n_values)} exceed n_compensation_max "
            f"{scenario.n_compensation_max}"
        )
    system_rows, table_rows, stations, first = [], [], [], None
    for k, rng in enumerate(trial_generators(seed, n_trials, stream)):
        ps = calibrated_station(rng)
        run = simulate_run(ps, scenario, rng)
        system, rows = trial_summary(run, scenario, n_values)
        system_rows.append({"trial": k} | system)
        table_rows += [{"trial": k} | r for r in rows]
        stations.append(ps)
        if k == 0:
            first = run
        if progress and (k + 1) % max(1, n_trials // 5) == 0:
            log_progress(
                progress, f"{k + 1}/{n_trials} stations in {time.perf_counter() - start:.1f} s"
            )
    return pd.DataFrame(system_rows), pd.DataFrame(table_rows), stations, first


def sensitivity_sweep(
    stations, scenario: Scenario, values: dict, seed: int, stream: int = 1, progress=False
):
    """The two headline shares as each assumption in ``values`` moves (others at default).

    Each calibrated station of ``stations`` is reused (its systematic error stays); the panels,
    readings and drift are drawn anew for each value. Returns one row per assumption, value
    and station: ``parameter, value, trial, within_0p3, r_above_0p7``.
    """
    start = time.perf_counter()
    rows = []
    for i, (name, vals) in enumerate(values.items()):
        if name not in SWEEP_LABELS:
            raise CalibrationError(f"unknown swept assumption {name!r}; use {list(SWEEP_LABELS)}")
        for j, v in enumerate(vals):
            sc = scenario.with_(**{name: float(v)})
            for k, ps in enumerate(stations):
                rng = np.random.default_rng([seed, stream, i, j, k])
                a = analyse_run(simulate_run(ps, sc, rng), sc.n_compensation)
                rows.append(
                    {
                        "parameter": name,
                        "value": float(v),
                        "trial": k,
                        "within_0p3": a["within_0p3"],
                        "r_above_0p7": a["r_above_0p7"],
                    }
                )
        log_progress(progress, f"sweep of {name}: {time.perf_counter() - start:.1f} s")
    return pd.DataFrame(rows)


def robot_error_sweep(
    seed: int, n_trials: int, scenario: Scenario, scales, stream: int = 2, progress=False
) -> pd.DataFrame:
    """The before-compensation and Table 1 figures as the true robot's manufacturing errors scale.

    For each factor of ``scales``, ``n_trials`` stations are drawn with the kinematic tolerances
    of ``data/robots/kuka_kr16_2.toml`` times the factor, calibrated and run through the paper's
    protocol with the other assumptions of ``scenario``. Station ``k`` gets the same generator
    at every factor (stream ``stream`` of ``seed``), so its robot errors keep their direction and
    only their size changes. Returns one row per factor and station: ``robot_error_scale``,
    ``trial`` and the figures of :func:`trial_summary` at ``scenario.n_compensation``.
    """
    scales = [float(s) for s in scales]
    if not scales:
        raise CalibrationError("scales is empty; give at least one factor on the tolerances")
    start = time.perf_counter()
    rows = []
    for scale in scales:
        for k, rng in enumerate(trial_generators(seed, n_trials, stream)):
            ps = calibrated_station(rng, robot_error_scale=scale)
            run = simulate_run(ps, scenario, rng)
            system, (table,) = trial_summary(run, scenario, [scenario.n_compensation])
            rows.append({"robot_error_scale": scale, "trial": k} | system | table)
        log_progress(progress, f"robot tolerances x {scale:g}: {time.perf_counter() - start:.1f} s")
    return pd.DataFrame(rows)


# ---------------------------------------------------------------------------------------------
# summaries, claims, figures


def _interval(v) -> tuple[float, float, float]:
    v = np.asarray(v, dtype=float)
    lo, hi = percentile_interval(v) if v.size >= 2 else (v[0], v[0])
    return float(np.median(v)), lo, hi


def _n_vectors(sub: pd.DataFrame) -> int:
    """Number of deviation coordinates of the trials in ``sub`` (174 for the paper's 58 points)."""
    n = sub["n_vectors"].to_numpy(int)
    if n.size == 0 or np.any(n != n[0]):
        raise CalibrationError(f"trials disagree on the number of coordinates: {sorted(set(n))}")
    return int(n[0])


def table1(trials: pd.DataFrame, n_compensation: int) -> tuple:
    """Table 1, both halves, over the trials at ``n_compensation``: per bin the median count,
    the median share (%) with its 95 % interval over trials, and the published count and share.

    The correlation half has one more row, the coordinates where ``r`` is undefined (fixed by
    the frame); its shares are of all coordinates (174 for the paper's 58 points).
    """
    sub = trials[trials["n_compensation"] == n_compensation]
    n_vectors = _n_vectors(sub)
    halves = []
    for prefix, labels, counts, percent in (
        ("deviation", DEVIATION_BINS, PUBLISHED_DEVIATION_COUNTS, PUBLISHED_DEVIATION_PERCENT),
        (
            "correlation",
            CORRELATION_BINS,
            PUBLISHED_CORRELATION_COUNTS,
            PUBLISHED_CORRELATION_PERCENT,
        ),
    ):
        rows = []
        columns = [f"{prefix}_bin{k}" for k in range(5)]
        values = [sub[c].to_numpy(float) for c in columns]
        if prefix == "correlation":
            labels = labels + ("undefined (fixed by the frame)",)
            counts, percent = counts + (0,), percent + (0.0,)
            values.append(sub["n_fixed"].to_numpy(float))
        for label, v, pc, pp in zip(labels, values, counts, percent, strict=True):
            med, lo, hi = _interval(100.0 * v / n_vectors)
            rows.append(
                {
                    "bin": label,
                    "count_median": float(np.median(v)),
                    "percent_median": med,
                    "percent_ci_low": lo,
                    "percent_ci_high": hi,
                    "published_count": pc,
                    "published_percent": pp,
                }
            )
        halves.append(pd.DataFrame(rows))
    return halves[0], halves[1]


def headline_summary(trials: pd.DataFrame) -> pd.DataFrame:
    """Per ``n``: median and 95 % interval of the two headline shares and of the share within
    +-0.3 mm before compensation and of all single readings."""
    rows = []
    for n, sub in trials.groupby("n_compensation", sort=True):
        row = {"n_compensation": int(n)}
        for col in ("within_0p3", "r_above_0p7", "within_0p3_uncompensated", "single_within_0p3"):
            row[col], row[f"{col}_low"], row[f"{col}_high"] = _interval(sub[col])
        rows.append(row)
    return pd.DataFrame(rows)


def summarise_sweep(sweep: pd.DataFrame) -> pd.DataFrame:
    """Median and 95 % interval of the two headline shares per assumption and value."""
    rows = []
    for (name, value), sub in sweep.groupby(["parameter", "value"], sort=False):
        row = {"parameter": name, "value": value}
        for col in ("within_0p3", "r_above_0p7"):
            row[col], row[f"{col}_low"], row[f"{col}_high"] = _interval(sub[col])
        rows.append(row)
    return pd.DataFrame(rows)


def summarise_robot_error_sweep(
    sweep: pd.DataFrame, n_compensation: int, notebook: str
) -> pd.DataFrame:
    """Per factor on the robot's tolerances (from :func:`robot_error_sweep`): the systematic size
    and the two headline shares, each with its 95 % interval over stations and the verdict of its
    claim computed by :func:`production_claims` on that factor's stations alone, and the median
    share within +-0.3 mm of the same products uncompensated."""
    rows = []
    for scale, sub in sweep.groupby("robot_error_scale", sort=False):
        claims = production_claims(sub, sub, n_compensation, notebook)
        row = {"robot_error_scale": scale, "stations": len(sub)}
        for claim, col in zip(
            claims, ("systematic_median_mm", "within_0p3", "r_above_0p7"), strict=True
        ):
            row |= {col: claim.reproduced, f"{col}_low": claim.ci_low, f"{col}_high": claim.ci_high}
            row[f"{claim.id.split('.')[1]}_verdict"] = claim.verdict
        row["within_0p3_uncompensated"] = float(np.median(sub["within_0p3_uncompensated"]))
        rows.append(row)
    return pd.DataFrame(rows)


def production_claims(
    systematic: pd.DataFrame, trials: pd.DataFrame, n_compensation: int, notebook: str
):
    """Claim rows ``hybrid.systematic``, ``hybrid.deviation``, ``hybrid.correlation``.

    * systematic: median over points of the size of the mean deviation before compensation
      (per trial) against the middle of the published 2-4 mm (value, factor 1.5); its effect is
      the excess over the median panel-to-panel scatter of the same trial (a size is never
      below 0, so 0 cannot stand for no effect: an error that is not systematic has a mean no
      larger than its scatter); the Lilliefors non-rejection rate and the share of significantly
      non-zero means in the note.
    * deviation: share within +-0.3 mm after compensation against 96.55 % (10 pp), its effect
      the gain over the same products uncompensated (paired per trial).
    * correlation: share of r > 0.7 (of the coordinates where r is defined) against 85.64 %
      (10 pp), no effect 0 % (unrelated readings almost never reach r > 0.7 over 30 products).
    """
    sub = trials[trials["n_compensation"] == n_compensation]
    lo_pub, hi_pub = PUBLISHED_SYSTEMATIC_MM
    v = verdict_vs_published(
        (lo_pub + hi_pub) / 2.0,
        systematic["systematic_median_mm"].to_numpy(),
        systematic["scatter_median_mm"].to_numpy(),
        kind="value",
        direction="higher",
    )
    lf = np.median(systematic["lilliefors_not_rejected"])
    nz = np.median(systematic["mean_nonzero"])
    v = replace(
        v,
        note=f"{v.note}; effect = size minus panel-to-panel scatter; Lilliefors does not reject "
        f"normality for {lf:.3g} % of the coordinates, mean significantly non-zero for "
        f"{nz:.3g} % (medians over trials)",
    )
    rows = [v.row("hybrid.systematic", "2-4", "mm", notebook)]
    v = verdict_vs_published(
        PUBLISHED_WITHIN_0P3,
        sub["within_0p3"].to_numpy(),
        sub["within_0p3_uncompensated"].to_numpy(),
        kind="percent",
        direction="higher",
    )
    v = replace(
        v,
        note=f"offset from {n_compensation} products; {v.note}; beyond 0.5 mm: "
        f"{np.median(sub['beyond_0p5']):.3g} % (published 0)",
    )
    rows.append(v.row("hybrid.deviation", f"{PUBLISHED_WITHIN_0P3}", "%", notebook))
    v = verdict_vs_published(
        PUBLISHED_R_ABOVE_0P7,
        sub["r_above_0p7"].to_numpy(),
        0.0,
        kind="percent",
        direction="higher",
    )
    v = replace(
        v,
        note=f"{v.note}; share of the {_n_vectors(sub) - int(np.median(sub['n_fixed']))} "
        "coordinates where r is defined",
    )
    rows.append(v.row("hybrid.correlation", f"{PUBLISHED_R_ABOVE_0P7}", "%", notebook))
    return rows


def fig6_figure(deviations, ids, point_id: str):
    """Fig. 6 of the paper for one point: (a) the deviations of each panel along x, y, z;
    (b) the normal densities fitted to them.

    ``deviations`` is ``(n, F, 3)`` in mm (``before_compensation(...)["deviations"]``), its
    points in the order of ``ids``; ``point_id`` names the point shown.
    """
    import matplotlib.pyplot as plt
    from scipy.stats import norm

    ids = list(ids)
    if point_id not in ids:
        raise CalibrationError(
            f"featured point {point_id!r} is not among the {len(ids)} feature points "
            f"(first ones: {ids[:5]})"
        )
    d = np.asarray(deviations, dtype=float)[:, ids.index(point_id)]
    fig, (ax_a, ax_b) = plt.subplots(1, 2, figsize=(11, 3.8), constrained_layout=True)
    panels = np.arange(1, d.shape[0] + 1)
    for k, axis in enumerate(AXES):
        ax_a.plot(panels, d[:, k], "o-", label=axis)
        mu, sd = d[:, k].mean(), d[:, k].std(ddof=1)
        grid = np.linspace(mu - 4 * sd, mu + 4 * sd, 200)
        ax_b.plot(grid, norm.pdf(grid, mu, sd), label=f"{axis}: mean {mu:.2f}, sd {sd:.3f} mm")
        ax_b.plot(d[:, k], np.zeros(d.shape[0]), "|", color=ax_b.lines[-1].get_color(), ms=12)
    ax_a.axhline(0.0, color="k", lw=0.8)
    ax_a.set_xlabel("panel")
    ax_a.set_ylabel("hybrid - CMM (mm)")
    ax_a.set_title(f"(a) deviations of point {point_id}, {d.shape[0]} panels")
    ax_a.legend(fontsize=8)
    ax_b.set_xlabel("hybrid - CMM (mm)")
    ax_b.set_ylabel("fitted normal density (1/mm)")
    ax_b.set_title("(b) normal fits")
    ax_b.legend(fontsize=8)
    for ax in (ax_a, ax_b):
        ax.grid(alpha=0.3)
    return fig


def n_sweep_figure(summary: pd.DataFrame):
    """The two headline shares against the number of products in the offset (Eq. 24)."""
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 3.8), constrained_layout=True)
    _headline_shares(ax, summary["n_compensation"], summary)
    ax.set_xlabel("products in the offset estimate (n of Eq. 24)")
    ax.set_ylabel("share of the vectors (%)")
    ax.set_title("Table 1 headline shares against n (median, 95 % interval over stations)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    return fig


def _headline_shares(ax, x, summary: pd.DataFrame) -> None:
    """Both headline shares of ``summary`` against ``x`` with their 95 % intervals, the published
    values dashed."""
    for col, label, pub in (
        ("within_0p3", "within +-0.3 mm", PUBLISHED_WITHIN_0P3),
        ("r_above_0p7", "r > 0.7", PUBLISHED_R_ABOVE_0P7),
    ):
        line = ax.plot(x, summary[col], "o-", label=label)[0]
        ax.fill_between(x, summary[f"{col}_low"], summary[f"{col}_high"], alpha=0.2)
        ax.axhline(pub, color=line.get_color(), ls="--", lw=1, label=f"published {pub} %")


def sensitivity_figure(summary: pd.DataFrame, scenario: Scenario):
    """One panel per swept assumption: both headline shares, the published values dashed, the
    default value dotted."""
    import matplotlib.pyplot as plt

    names = list(dict.fromkeys(summary["parameter"]))
    fig, axes = plt.subplots(1, len(names), figsize=(3.6 * len(names), 3.8), squeeze=False)
    fig.set_layout_engine("constrained")
    for ax, name in zip(axes[0], names, strict=True):
        sub = summary[summary["parameter"] == name]
        _headline_shares(ax, sub["value"], sub)
        ax.axvline(getattr(scenario, name), color="k", ls=":", lw=1)
        ax.set_xlabel(SWEEP_LABELS[name])
        ax.set_ylim(-3, 103)
        ax.grid(alpha=0.3)
    axes[0][0].set_ylabel("share of the vectors (%)")
    axes[0][0].legend(fontsize=8, loc="lower left")
    fig.suptitle(
        "Table 1 headline shares as each assumption moves (dashed: published; dotted: default)"
    )
    return fig


def robot_error_figure(summary: pd.DataFrame, default: float = 1.0):
    """The sweep of the robot's manufacturing errors (:func:`summarise_robot_error_sweep`):
    (a) the systematic size before compensation against the published 2-4 mm, each factor
    labelled with its ``hybrid.systematic`` verdict; (b) the two headline shares after
    compensation, and the share within +-0.3 mm of the same products uncompensated ("raw").
    The default factor is dotted."""
    import matplotlib.pyplot as plt

    fig, (ax_a, ax_b) = plt.subplots(1, 2, figsize=(11, 3.8), constrained_layout=True)
    x = summary["robot_error_scale"]
    lo, hi = PUBLISHED_SYSTEMATIC_MM
    mid = (lo + hi) / 2.0
    ax_a.axhspan(lo, hi, color="0.85", label=f"published {lo:g}-{hi:g} mm")
    # the magnitude band of the verdict: the middle of the range within the register's factor 1.5
    for k, edge in enumerate((mid / 1.5, mid * 1.5)):
        label = f"verdict band {mid / 1.5:g}-{mid * 1.5:g} mm" if k == 0 else None
        ax_a.axhline(edge, color="0.4", ls="--", lw=1, label=label)
    y = summary["systematic_median_mm"]
    ax_a.plot(x, y, "o-", label="median point, median over stations")
    ax_a.fill_between(
        x, summary["systematic_median_mm_low"], summary["systematic_median_mm_high"], alpha=0.2
    )
    for xi, yi, verdict in zip(x, y, summary["systematic_verdict"], strict=True):
        ax_a.annotate(
            verdict, (xi, yi), textcoords="offset points", xytext=(-6, 8), fontsize=7, rotation=30
        )
    ax_a.set_ylabel("systematic size before compensation (mm)")
    ax_a.set_title("(a) hybrid.systematic (95 % interval over stations)")
    ax_a.legend(fontsize=8, loc="upper left")
    _headline_shares(ax_b, x, summary)
    ax_b.plot(
        x, summary["within_0p3_uncompensated"], "s:", color="0.4", label="within +-0.3 mm, raw"
    )
    ax_b.set_ylim(-3, 103)
    ax_b.set_ylabel("share of the vectors (%)")
    ax_b.set_title("(b) Table 1 headline shares after compensation")
    ax_b.legend(fontsize=8, loc="lower left")
    for ax in (ax_a, ax_b):
        ax.axvline(default, color="k", ls=":", lw=1)
        ax.set_xlabel(ROBOT_ERROR_LABEL)
        ax.grid(alpha=0.3)
    return fig


def sensor_pose_check(ps: ProductionStation) -> np.ndarray:
    """Where each flexible feature falls in the sensor frame on the true robot (mm), a check
    that the program puts it near the middle of the measuring field."""
    st, f = ps.station, ps.features
    actual = st.true.fk_many(ps.program) @ st.sensor2flange_true
    p = geo.apply(geo.invert(st.base2work_nominal), f.cad[f.flexible])
    return _transform_points(geo.invert(actual), p)


def station_data(hybrid_csv: str, cmm_csv: str, ids, simulated_run: dict):
    """The measurements of one station: the user's CSVs if both are given, else a simulated run.

    Returns ``(source, ids, run)`` with ``run = {phase: (hybrid, cmm)}``.
    """
    if bool(hybrid_csv) != bool(cmm_csv):
        raise CalibrationError("give both hybrid_csv and cmm_csv, or neither")
    if hybrid_csv:
        ids, run = read_measurements(hybrid_csv, cmm_csv)
        n = {p: run[p][0].shape[0] for p in run}
        if set(run) != set(PHASES):
            raise CalibrationError(f"the tables hold products of phases {list(run)}; need {PHASES}")
        return f"measured tables {hybrid_csv} and {cmm_csv} ({n} products)", ids, run
    return "one simulated station (trial 0)", list(ids), simulated_run


def station_table1(run: dict, n_compensation: int) -> pd.DataFrame:
    """Table 1 of one station beside the published one: half, bin, count, share (%)."""
    a = analyse_run(run, n_compensation)
    n_vec = a["n_vectors"]
    rows = []
    for half, labels, counts, pub_c, pub_p in (
        (
            "deviation",
            DEVIATION_BINS,
            a["deviation_counts"],
            PUBLISHED_DEVIATION_COUNTS,
            PUBLISHED_DEVIATION_PERCENT,
        ),
        (
            "correlation",
            CORRELATION_BINS + ("undefined (fixed by the frame)",),
            np.r_[a["correlation_counts"], a["n_fixed"]],
            PUBLISHED_CORRELATION_COUNTS + (0,),
            PUBLISHED_CORRELATION_PERCENT + (0.0,),
        ),
    ):
        for label, c, pc, pp in zip(labels, counts, pub_c, pub_p, strict=True):
            rows.append(
                {
                    "half": half,
                    "bin": label,
                    "count": int(c),
                    "percent": 100.0 * c / n_vec,
                    "published_count": pc,
                    "published_percent": pp,
                }
            )
    return pd.DataFrame(rows)


def assumptions_table(scenario: Scenario) -> pd.DataFrame:
    """The production assumptions of a scenario with where each comes from."""
    cfg = load_production_config()
    rows = [
        ("part_sigma_mm", scenario.part_sigma_mm, "assumption: +-2 mm tolerance (4.3), Cp 1.33"),
        ("feature_sigma_mm", scenario.feature_sigma_mm, "assumption: line-laser feature noise"),
        ("repeatability_mm", scenario.repeatability_mm, "paper 4.1: +-0.06 mm"),
        ("drift_sigma_mm", scenario.drift_sigma_mm, "assumption: residual drift over a month"),
        ("cmm_sigma_mm", scenario.cmm_sigma_mm, "assumption: CMM probing of sheet metal"),
        ("n_before", scenario.n_before, "paper 4.3: 10 panels (Fig. 6)"),
        ("n_compensation", scenario.n_compensation, "paper 4.3: usually 10-20 products"),
        ("n_follow_up", scenario.n_follow_up, "paper 4.3: 30 products over a month"),
        ("panel_mm", " x ".join(f"{v:g}" for v in cfg["panel"]["size_mm"]), "paper 4.1"),
    ]
    return pd.DataFrame(rows, columns=["assumption", "value", "source"]).astype({"value": str})


def summarise_systematic(systematic: pd.DataFrame) -> pd.DataFrame:
    """Median and 95 % interval over trials of each before-compensation figure."""
    rows = []
    for col in systematic.columns.drop("trial"):
        med, lo, hi = _interval(systematic[col])
        rows.append({"figure": col, "median": med, "ci_low": lo, "ci_high": hi})
    return pd.DataFrame(rows)
