"""Inputs of the ``dualarm`` station derived from what the paper states about its sensors.

The paper states one accuracy for its binocular structured-light sensors, 0.029 mm, the mean of
four diameter errors of sphere fits (0.022 / 0.047 mm for sensor 1 on spheres A / B, 0.018 /
0.029 mm for sensor 2; sec. 4.1), and the cameras' 1280 x 1024 pixels. The scenario keeps these
statements (``sensor.stated_accuracy_mm``, ``sensor.diameter_errors_mm``, ``camera``); the
functions here turn them into the inputs the simulation needs, through the imaging geometry of
the scenario (focal length ``f``, stereo baseline ``B``, working distance ``Z``):

* the marker-centre noise (:func:`marker_sigma_px`): a point triangulated by a stereo head has
  the depth error ``sigma_z = Z^2 sigma_d / (f B)``, with the disparity noise ``sigma_d =
  sqrt(2) sigma_px`` of two independent centres; read the stated accuracy as ``sigma_z`` of a
  triangulated marker and solve for ``sigma_px``;
* the Eq. 10 weight of a triangulated marker (:func:`marker_sigma_mm`): the stated accuracy;
* the per-view systematic error of a sphere scan (:func:`sphere_fit_sigma_mm`): a diameter error
  ``|dD|`` is twice a radial error; read as a normal radial error per view, the mean ``|dD| = 2
  sigma sqrt(2 / pi)``;
* the points a scan holds (:func:`cap_points`): one point per camera pixel over the image of the
  sphere cap the sensor sees, ``pi (r sin(theta_max) f / Z)^2``.

Each value is read at the stated accuracy (the scenario's value) and over the spread of the four
diameter errors (the ends of its range). :func:`derived_inputs` lists them by dotted key; a test
checks that ``data/dualarm/scenario.toml`` holds exactly what they compute.
"""

from __future__ import annotations

import math

from calstudy.core.errors import CalibrationError
from calstudy.papers.dualarm.schema import Scenario

#: significant digits the scenario file keeps of a derived value
DIGITS = 3


def _geometry(scn: Scenario) -> tuple[float, float, float]:
    """``(f px, baseline mm, working distance mm)`` of the scenario."""
    return scn.camera.fx_px, scn.stereo.baseline_mm, scn.sensor.working_distance_mm


def marker_sigma_px(scn: Scenario, accuracy_mm: float) -> float:
    """Centre noise (px per image coordinate) of a marker triangulated to ``accuracy_mm`` in
    depth at the working distance: ``sigma_px = accuracy f B / (sqrt(2) Z^2)``.

    Parameters
    ----------
    scn : Scenario
        The station (``camera.fx_px``, ``stereo.baseline_mm``, ``sensor.working_distance_mm``).
    accuracy_mm : float
        Depth error (1 sigma) of a triangulated point, mm.

    Returns
    -------
    float
        The centre noise, px.

    Raises
    ------
    CalibrationError
        If ``accuracy_mm`` is not a positive finite number.
    """
    f, baseline, z = _geometry(scn)
    return _positive("accuracy_mm", accuracy_mm) * f * baseline / (math.sqrt(2.0) * z**2)


def marker_sigma_mm(accuracy_mm: float) -> float:
    """The depth noise (mm) of a marker triangulated at the working distance, the weight of
    Eq. 10 there: the stated accuracy itself.

    Raises
    ------
    CalibrationError
        If ``accuracy_mm`` is not a positive finite number.
    """
    return _positive("accuracy_mm", accuracy_mm)


def sphere_fit_sigma_mm(diameter_error_mm: float) -> float:
    """Standard deviation (mm) of a view's radial error whose mean absolute diameter error is
    ``diameter_error_mm``: ``|dD| = 2 |dr|`` and ``E|dr| = sigma sqrt(2 / pi)``.

    Raises
    ------
    CalibrationError
        If ``diameter_error_mm`` is not a positive finite number.
    """
    return 0.5 * _positive("diameter_error_mm", diameter_error_mm) * math.sqrt(math.pi / 2.0)


def cap_points(scn: Scenario, radius_mm: float) -> float:
    """Camera pixels over the image of the cap of a sphere of ``radius_mm`` that the sensor
    sees at the working distance (incidence below ``sensor.max_incidence_deg``):
    ``pi (r sin(theta_max) f / Z)^2``, one structured-light point per pixel.

    Raises
    ------
    CalibrationError
        If ``radius_mm`` is not a positive finite number.
    """
    f, _, z = _geometry(scn)
    r = _positive("radius_mm", radius_mm) * math.sin(scn.sensor.max_incidence) * f / z
    return math.pi * r**2


def _positive(name: str, value: float) -> float:
    value = float(value)
    if not (math.isfinite(value) and value > 0):
        raise CalibrationError(f"{name} = {value!r}: must be a positive finite number")
    return value


def rounded(value: float, digits: int = DIGITS) -> float:
    """``value`` to ``digits`` significant digits, as the scenario file keeps it."""
    return float(f"{value:.{digits - 1}e}")


def derived_inputs(scn: Scenario) -> dict[str, dict]:
    """The derived inputs of the scenario: dotted key -> ``value`` (at the stated accuracy),
    ``range`` (over the spread of the paper's diameter errors), both to :data:`DIGITS`
    significant digits, and ``how`` (the derivation in words).

    Parameters
    ----------
    scn : Scenario
        The station whose statements and geometry the values follow from.

    Returns
    -------
    dict of str to dict
        ``detection.sigma_px``, ``detection.marker_sigma_mm``, ``sensor.sphere_fit_sigma_mm``.
    """
    acc = scn.sensor.stated_accuracy_mm
    lo, hi = min(scn.sensor.diameter_errors_mm), max(scn.sensor.diameter_errors_mm)
    f, baseline, z = _geometry(scn)
    out = {}
    for key, fn, how in (
        (
            "detection.sigma_px",
            lambda a: marker_sigma_px(scn, a),
            f"the stated accuracy as the depth error Z^2 sqrt(2) sigma_px / (f B) of a "
            f"triangulated marker, f = {f:g} px, B = {baseline:g} mm, Z = {z:g} mm",
        ),
        ("detection.marker_sigma_mm", marker_sigma_mm, "the stated accuracy itself"),
        (
            "sensor.sphere_fit_sigma_mm",
            sphere_fit_sigma_mm,
            "a diameter error is twice a radial error; mean |dD| = 2 sigma sqrt(2 / pi)",
        ),
    ):
        out[key] = {
            "value": rounded(fn(acc)),
            "range": [rounded(fn(lo)), rounded(fn(hi))],
            "how": how,
        }
    return out


__all__ = [
    "cap_points",
    "derived_inputs",
    "marker_sigma_mm",
    "marker_sigma_px",
    "rounded",
    "sphere_fit_sigma_mm",
]
