"""The parameters of each notebook, checked before the notebook uses them.

Every notebook's first cell after its ``parameters`` cell (and after the cell papermill injects
there) calls :func:`check_parameters` with its own name and its namespace: the values are checked
against the notebook's schema (one :class:`~calstudy.core.schema.Schema` per notebook, below),
and a bad value stops the run with one :class:`~calstudy.core.errors.CalibrationError` naming
the notebook, the parameter, the value and what is allowed::

    notebook 06_handeye_your_cell parameters: n_trials = -5: must be >= 0 and <= 100000

A count is bounded above (:data:`MAX_COUNT`) so that a typing slip cannot ask for an allocation
no machine has; a noise level may be 0 where the notebook reads 0 as "none" or "estimate it".
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Annotated, Any, Literal

from pydantic import Field, model_validator

from calstudy.core.errors import CalibrationError
from calstudy.core.schema import NonNegativeFinite, PositiveFinite, Schema, validate

#: Largest trial count, sweep length or pose count a notebook parameter may ask for.
MAX_COUNT = 100_000

Count = Annotated[int, Field(ge=1, le=MAX_COUNT)]
#: replications whose median has a 95 % order-statistic interval (at least 6)
Replications = Annotated[int, Field(ge=6, le=MAX_COUNT)]
CountOrNone = Annotated[int, Field(ge=0, le=MAX_COUNT)]
Products = Annotated[int, Field(ge=3, le=MAX_COUNT)]
Positives = Annotated[list[PositiveFinite], Field(min_length=1, max_length=MAX_COUNT)]
NonNegatives = Annotated[list[NonNegativeFinite], Field(min_length=1, max_length=MAX_COUNT)]
Counts = Annotated[list[Count], Field(min_length=1, max_length=MAX_COUNT)]
Tilts = Annotated[
    list[Annotated[float, Field(ge=0, lt=90, allow_inf_nan=False)]],
    Field(min_length=1, max_length=MAX_COUNT),
]
Point3 = Annotated[
    list[Annotated[float, Field(allow_inf_nan=False)]], Field(min_length=3, max_length=3)
]


class NotebookParameters(Schema):
    """The parameters every notebook with trials has."""

    seed: Annotated[int, Field(ge=0)]
    results_dir: str
    n_jobs: int | None
    scheduler: str
    cache_dir: str
    progress: bool

    @model_validator(mode="after")
    def _jobs(self) -> NotebookParameters:
        if self.n_jobs is not None and (self.n_jobs == 0 or self.n_jobs < -1):
            raise ValueError(
                f"n_jobs = {self.n_jobs}: must be None or -1 (all cores) or a "
                "positive number of worker processes"
            )
        return self


class RobustnessParameters(NotebookParameters):
    """The parameters of a notebook with a robustness map
    (:func:`calstudy.core.robustness.robustness_map`): trials per screened end and per judged
    point, values per swept input, and the inputs screened (empty: all)."""

    n_screen_trials: Replications
    n_robust_trials: Replications
    robust_sweep_size: Annotated[int, Field(ge=2, le=MAX_COUNT)]
    robustness_inputs: list[str]


class Notebook01(RobustnessParameters):
    """``01_hybrid_global_calibration``."""

    n_trials: Count
    n_sweep_trials: Count
    noise_levels_mm: Positives
    rotation_moves: Annotated[list[Annotated[int, Field(ge=3, le=MAX_COUNT)]], Field(min_length=1)]
    centre_floors_mm: NonNegatives
    correlation_scales: Annotated[
        list[Annotated[float, Field(ge=0, le=1, allow_inf_nan=False)]],
        Field(min_length=1, max_length=MAX_COUNT),
    ]
    translation_ranges_mm: Positives | None
    across_plane_ranges_mm: Positives | None
    pixel_sigmas: NonNegatives | None
    penalties: Positives
    n_penalty_trials: Count
    n_robots: Count
    measurements_csv: str
    sensor_sigma_mm: (
        PositiveFinite | Annotated[list[PositiveFinite], Field(min_length=3, max_length=3)]
    )
    misfit: Literal["raise", "flag"]


class Notebook02(RobustnessParameters):
    """``02_hybrid_production_compensation``."""

    n_trials: Count
    n_values: Annotated[list[Products], Field(min_length=1, max_length=MAX_COUNT)]
    n_sweep_trials: Count
    robot_error_scales: NonNegatives
    n_robot_sweep_trials: Count
    featured_point: Annotated[str, Field(min_length=1)]
    hybrid_csv: str
    cmm_csv: str
    n_part_trials: Count
    part_sigmas_mm: Positives

    @model_validator(mode="after")
    def _both_files(self) -> Notebook02:
        if bool(self.hybrid_csv) != bool(self.cmm_csv):
            raise ValueError(
                f"hybrid_csv = {self.hybrid_csv!r} and cmm_csv = {self.cmm_csv!r}: "
                "give both files (the same products and points) or neither"
            )
        return self


class Notebook03(RobustnessParameters):
    """``03_selfcal_one_step_identification``."""

    n_trials: Count
    n_sweep_trials: Count
    noise_scales: NonNegatives
    scenario_toml: str
    measurements_dir: str
    requirement_mm: PositiveFinite
    n_selection_trials: Count
    selection_sizes: Counts
    candidates_per_sphere: Count
    n_pose_replications: Replications


class Notebook04(RobustnessParameters):
    """``04_binocular_correction``."""

    n_trials: Count
    n_field_trials: Count
    n_sweep_trials: Count
    robot_scales: NonNegatives
    calibration_scales: NonNegatives
    f_numbers: Annotated[list[PositiveFinite], Field(min_length=2, max_length=MAX_COUNT)]
    focus_distances_mm: Positives
    dot_diameters_mm: Positives
    defocus_depths_mm: Positives
    defocus_tilts_deg: Tilts
    scenario_dir: str
    #: the defocus mechanisms run, the claims table's first
    mechanisms: Annotated[list[Literal["gaussian", "rim"]], Field(min_length=1, max_length=2)]
    #: rim (radius, distance) mm at which the rim mechanism is calibrated, its main run's first
    rim_geometries_mm: Annotated[
        list[Annotated[list[PositiveFinite], Field(min_length=2, max_length=2)]],
        Field(min_length=1, max_length=MAX_COUNT),
    ]


class Notebook05(RobustnessParameters):
    """``05_dualarm_global_calibration``."""

    n_trials: Count
    n_pilot_trials: Count
    drift_scales: NonNegatives
    plate_sigmas_px: NonNegatives
    n_sweep_trials: Count
    sweep_bridge_views: Counts
    sweep_bridge_tilts_deg: Tilts
    sweep_poses: Annotated[list[Annotated[int, Field(ge=3, le=MAX_COUNT)]], Field(min_length=1)]
    n_budget_trials: Count
    scenario_toml: str
    robustness_caps: dict[str, PositiveFinite]


class Notebook06(NotebookParameters):
    """``06_handeye_your_cell``: ``n_trials = 0`` skips the Monte Carlo check; both noise
    levels 0 estimates the noise from the residuals, both positive gives it."""

    poses_csv: str
    setup: Literal["eye_in_hand", "eye_to_hand"]
    n_poses: Annotated[int, Field(ge=3, le=MAX_COUNT)]
    n_duplicates: CountOrNone
    outlier_mm: NonNegativeFinite
    outlier_deg: NonNegativeFinite
    sigma_rot_rad: NonNegativeFinite
    sigma_trans_mm: NonNegativeFinite
    robust: Literal["huber", "cauchy", "ransac"] | None
    tool_point_mm: Point3
    n_trials: CountOrNone

    @model_validator(mode="after")
    def _sigmas(self) -> Notebook06:
        if (self.sigma_rot_rad > 0) != (self.sigma_trans_mm > 0):
            raise ValueError(
                f"sigma_rot_rad = {self.sigma_rot_rad} and sigma_trans_mm = "
                f"{self.sigma_trans_mm}: give both noise levels (> 0), or both 0 to estimate "
                "them from the residuals"
            )
        return self


#: The schema of each notebook, by its file name without ``.ipynb``.
SCHEMAS: dict[str, type[NotebookParameters]] = {
    "01_hybrid_global_calibration": Notebook01,
    "02_hybrid_production_compensation": Notebook02,
    "03_selfcal_one_step_identification": Notebook03,
    "04_binocular_correction": Notebook04,
    "05_dualarm_global_calibration": Notebook05,
    "06_handeye_your_cell": Notebook06,
}


def check_parameters(notebook: str, namespace: Mapping[str, Any]) -> NotebookParameters:
    """The parameters of ``notebook`` read from ``namespace`` (its ``globals()``), checked.

    Parameters
    ----------
    notebook : str
        The notebook's file name without ``.ipynb``, a key of :data:`SCHEMAS`.
    namespace : mapping
        Where the parameters cell (and papermill's injected cell) put the values.

    Returns
    -------
    NotebookParameters
        The checked values (a frozen pydantic model of the notebook's schema).

    Raises
    ------
    CalibrationError
        For an unknown notebook, a parameter missing from ``namespace``, or a value outside its
        domain: the message names the notebook, the parameter, the value and what is allowed.
    """
    if notebook not in SCHEMAS:
        raise CalibrationError(
            f"no parameter schema for notebook {notebook!r}; known: {list(SCHEMAS)}"
        )
    model = SCHEMAS[notebook]
    missing = [name for name in model.model_fields if name not in namespace]
    if missing:
        raise CalibrationError(f"notebook {notebook}: parameter(s) {missing} are not defined")
    values = {name: namespace[name] for name in model.model_fields}
    return validate(model, values, f"notebook {notebook} parameters")
