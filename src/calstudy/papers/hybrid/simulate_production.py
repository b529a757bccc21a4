"""The hybrid station in production (hybrid paper, section 4.3): panels measured on the station
and on a CMM.

A calibrated station (:class:`ProductionStation`, built by
:func:`calstudy.papers.hybrid.experiments.calibrate`) measures a run of rear underbody panels. Each
panel carries the 58 feature points of :func:`calstudy.papers.hybrid.scenario.panel_features`: 48
measured by the flexible sensor, one taught robot pose each, and 10 by the stationary sensors, the
first three of which are the datums A (slot), B (hole) and C (plane) that fix the workpiece frame
by the 3-2-1 rule. A CMM measures the same panels. Every reading is in mm, in the workpiece frame
(WF).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from calstudy.core import geometry as geo
from calstudy.core.errors import CalibrationError
from calstudy.core.montecarlo import streams
from calstudy.estimators.workpiece import rps_frame_batch
from calstudy.papers.hybrid.scenario import Features, Scenario
from calstudy.papers.hybrid.simulate import HybridStation, repeatability_joint_sigma

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
    fixture pose, the stand-off. It depends on no random draw, so it is kept, by the robot and
    the taught flange poses: what the inverse kinematics reads, so a station with another
    stand-off or fixture never reuses another station's program.
    """
    poses = sensor_poses(station, features) @ geo.invert(station.sensor2flange_true)
    key = (station.nominal.key(), poses.tobytes())
    if key not in _PROGRAM_CACHE:
        q = []
        for pid, pose in zip(np.array(features.ids)[features.flexible], poses, strict=True):
            try:
                q.append(station.solve_ik(station.nominal, pose))
            except CalibrationError as exc:
                raise CalibrationError(f"feature {pid} is out of reach: {exc}") from exc
        program = np.array(q)
        program.flags.writeable = False  # shared by every station with these poses
        _PROGRAM_CACHE[key] = program
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
    _reported: dict = field(default_factory=dict, repr=False, compare=False)

    def joint_sigma(self, repeatability_mm: float) -> float:
        """Joint noise (rad) for a repeatability of +-``repeatability_mm`` (3 sigma)."""
        if repeatability_mm not in self._joint_sigmas:
            self._joint_sigmas[repeatability_mm] = repeatability_joint_sigma(
                self.station, repeatability_mm / 3.0
            )
        return self._joint_sigmas[repeatability_mm]

    def reported_sensor2base(self) -> np.ndarray:
        """``sensor2base`` the station computes with at each program pose: nominal FK, calibrated
        hand-eye. The same at every panel, so computed once per program, robot and hand-eye
        (a read-only array)."""
        nominal = self.station.nominal
        key = (self.program.tobytes(), self.sensor2flange.tobytes(), nominal.key())
        if key not in self._reported:
            poses = nominal.fk_many(self.program) @ self.sensor2flange
            poses.flags.writeable = False
            self._reported.clear()
            self._reported[key] = poses
        return self._reported[key]


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
    CMM reports the true WF coordinates with ``cmm_sigma`` noise. Panels, flexible readings,
    stationary readings and the CMM draw from their own streams of ``rng``.

    Returns
    -------
    hybrid, cmm : (n_products, F, 3) arrays
        WF coordinates, mm.
    """
    st, f = ps.station, ps.features
    n = int(n_products)
    if n < 1:
        raise CalibrationError(f"n_products is {n_products}; at least 1 panel needed")
    panels, flexible, stationary, cmm_rng = streams(
        rng, "panels", "flexible readings", "stationary readings", "cmm"
    )
    truth_work, truth_base = _draw_panels(ps, scenario, n, panels)
    measured_base = np.empty_like(truth_base)
    fl = f.flexible
    measured_base[:, fl] = _flexible_readings(ps, scenario, truth_base[:, fl], flexible)
    sn = f.stationary
    measured_base[:, sn] = _stationary_readings(ps, scenario, truth_base[:, sn], stationary)
    base2work = rps_frame_batch(measured_base[:, sn[:3]], st.datums_work, st.base2work_nominal)
    hybrid = _transform_points(base2work[:, None], measured_base)
    # the frame is defined by these coordinates: exactly CAD in both systems
    hybrid[:, f.fixed] = f.cad[f.fixed]
    if drift is not None:
        hybrid += np.where(f.fixed, 0.0, np.asarray(drift, dtype=float))
    cmm_noise = cmm_rng.normal(0.0, scenario.production.cmm.sigma_mm, truth_work.shape)
    cmm = truth_work + cmm_noise
    cmm[:, f.fixed] = f.cad[f.fixed]
    return hybrid, cmm


def _draw_panels(
    ps: ProductionStation, scenario: Scenario, n: int, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray]:
    """True feature coordinates of ``n`` new panels ``(n, F, 3)`` in WF and, clamped on the
    fixture, in the base frame."""
    st, f = ps.station, ps.features
    dev = rng.normal(0.0, scenario.production.variation.part_sigma_mm, (n, len(f.ids), 3))
    dev[:, f.fixed] = 0.0
    truth_work = f.cad + dev
    wcfg = st.config.workpiece
    work2base = geo.perturb(
        np.broadcast_to(geo.invert(st.base2work_nominal), (n, 4, 4)),
        np.deg2rad(wcfg.placement_sigma_deg),
        wcfg.placement_sigma_mm,
        rng,
    )
    return truth_work, _transform_points(work2base[:, None], truth_work)


def _flexible_readings(
    ps: ProductionStation, scenario: Scenario, truth_base: np.ndarray, rng: np.random.Generator
) -> np.ndarray:
    """Flexible-sensor readings ``(n, F_flex, 3)`` in the base frame as the station computes
    them: true robot at the program joints (plus repeatability), nominal computation."""
    st = ps.station
    n = truth_base.shape[0]
    sigma_q = ps.joint_sigma(scenario.station.robot.repeatability_mm)
    q = ps.program[None] + rng.normal(0.0, sigma_q, (n,) + ps.program.shape)
    actual = st.true.fk_many(q.reshape(-1, q.shape[-1])).reshape(n, truth_base.shape[1], 4, 4)
    sensor2base = actual @ st.sensor2flange_true
    in_sensor = _transform_points(geo.invert(sensor2base), truth_base)
    in_sensor += rng.normal(0.0, scenario.production.sensors.feature_sigma_mm, in_sensor.shape)
    return _transform_points(ps.reported_sensor2base()[None], in_sensor)


def _stationary_readings(
    ps: ProductionStation, scenario: Scenario, truth_base: np.ndarray, rng: np.random.Generator
) -> np.ndarray:
    """Stationary-sensor readings ``(n, 10, 3)`` in the base frame: the true sensor pose for the
    reading, the calibrated pose for the computation."""
    st, f = ps.station, ps.features
    cams = f.sensor[f.stationary] - 1
    in_cam = _transform_points(geo.invert(st.statcam2base_true[cams])[None], truth_base)
    feature_sigma = scenario.production.sensors.feature_sigma_mm
    sigma = np.where(np.isin(cams, (0, 1, 2)), st.datum_sigma, feature_sigma)
    in_cam += rng.normal(0.0, 1.0, in_cam.shape) * sigma[None, :, None]
    return _transform_points(ps.statcam2base[cams][None], in_cam)


def simulate_run(ps: ProductionStation, scenario: Scenario, rng: np.random.Generator) -> dict:
    """The paper's protocol on one station: ``n_compensation_max`` products after installation
    (the first ``n_before`` are the ones of Fig. 6), then, after a drift of ``drift_sigma`` per
    coordinate, ``n_follow_up`` products. Returns ``{phase: (hybrid, cmm)}`` for :data:`PHASES`
    and ``"drift"``, the ``(F, 3)`` shift added to the follow-up readings (0 at the coordinates
    fixed by the frame), which a measured station does not know. The products before the drift,
    the drift and the follow-up products draw from their own streams of ``rng``."""
    before, drift_rng, after = streams(rng, "compensation products", "drift", "follow-up products")
    protocol = scenario.production.protocol
    comp = simulate_products(ps, scenario, protocol.n_compensation_max, before)
    drift = drift_rng.normal(0.0, scenario.production.drift.sigma_mm, (len(ps.features.ids), 3))
    follow = simulate_products(ps, scenario, protocol.n_follow_up, after, drift=drift)
    drift = np.where(ps.features.fixed, 0.0, drift)
    return {"compensation": comp, "follow-up": follow, "drift": drift}


def sensor_pose_check(ps: ProductionStation) -> np.ndarray:
    """Where each flexible feature falls in the sensor frame on the true robot (mm), a check
    that the program puts it near the middle of the measuring field."""
    st, f = ps.station, ps.features
    actual = st.true.fk_many(ps.program) @ st.sensor2flange_true
    p = geo.apply(geo.invert(st.base2work_nominal), f.cad[f.flexible])
    return _transform_points(geo.invert(actual), p)
