"""The joint calibration of notebook 05's two nuisance inputs: known answers on made-up pilots
and on a small real drift pilot, the refusals, and the rounding of the value fed onwards."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from calstudy.core.errors import CalibrationError
from calstudy.core.jointcal import Baseline
from calstudy.core.montecarlo import run
from calstudy.core.stats import round_to_uncertainty
from calstudy.papers.dualarm import experiments
from calstudy.papers.dualarm import report_calibration as rc
from calstudy.papers.dualarm.scenario import load_published

PUBLISHED = load_published()
PAIRS = [(arm, sphere, before) for arm, sphere, before, _ in PUBLISHED.icp.rows]
SCALES = (1.0, 1.5, 2.0, 3.0)


def drift_pilot(truth=1.8, off=None, n=30, scales=SCALES, sigma=0.3):
    """Each pair's before-ICP error proportional to the scale, meeting the paper's value at
    ``truth`` (pair ``off``: ``(column, factor)`` misses it by that factor at every scale), with
    the same lognormal trial noise (``sigma`` of its log) at every scale, of median 1."""
    noise = np.exp(np.random.default_rng(5).normal(0.0, sigma, (n, len(PAIRS))))
    noise /= np.median(noise, axis=0)  # each pair's median exactly on its line
    rows = []
    for s in scales:
        for t in range(n):
            row = {"drift_scale": s, "trial": t}
            for k, (arm, sphere, before) in enumerate(PAIRS):
                row[rc.pair_column(arm, sphere)] = before * s / truth * noise[t, k]
            rows.append(row)
    pilot = pd.DataFrame(rows)
    if off:
        pilot[off[0]] *= off[1]
    return pilot


def test_the_joint_fit_recovers_a_known_drift_scale(scenario):
    fit = rc.drift_fit(drift_pilot(1.8), PUBLISHED)
    assert fit.identified and not fit.at_edge
    assert len(fit.met()) == 4
    assert fit.value == pytest.approx(1.8, abs=2 * fit.uncertainty)
    assert fit.value == pytest.approx(1.8, rel=1e-3)
    # each pair's tolerance is two of its spreads over the pilot's trials (the made-up noise)
    pilot = drift_pilot(1.8)
    at1 = pilot[pilot["drift_scale"] == 1.0]
    own = [np.std(np.log(at1[rc.pair_column(a, s)]), ddof=1) for a, s, _ in PAIRS]
    np.testing.assert_allclose(fit.agreement["tolerance"], np.expm1(2 * np.array(own)))


def test_a_pair_that_no_shared_scale_meets_is_reported(scenario):
    pilot = drift_pilot(1.8, off=("before_1B_mm", 4.0))
    fit = rc.drift_fit(pilot, PUBLISHED)
    assert not fit.identified
    assert "before_1B_mm" not in fit.met() and len(fit.met()) == 3
    table = rc.calibration_table(fit, pilot, "drift_scale")
    text = rc.drift_text(table)
    assert "does not meet arm 1 sphere B" in text and "All four are met" not in text
    fine = rc.calibration_table(rc.drift_fit(drift_pilot(1.8), PUBLISHED), pilot, "drift_scale")
    assert "All four are met" in rc.drift_text(fine)


def test_the_drift_text_says_whether_the_paper_figures_tell_the_pairs_apart(scenario):
    ratio = f"{max(b for *_, b in PAIRS) / min(b for *_, b in PAIRS):.2f}"
    wide = drift_pilot(1.8, sigma=0.5)
    text = rc.drift_text(rc.calibration_table(rc.drift_fit(wide, PUBLISHED), wide, "drift_scale"))
    assert f"within a factor {ratio} of one another" in text
    assert "cannot tell the pairs apart" in text and "in the paper's order" in text
    narrow = drift_pilot(1.8, sigma=0.05)
    table = rc.calibration_table(rc.drift_fit(narrow, PUBLISHED), narrow, "drift_scale")
    text = rc.drift_text(table)
    assert f"span a factor {ratio}, beyond" in text and "cannot tell" not in text
    off = drift_pilot(1.8, off=("before_1B_mm", 4.0))
    text = rc.drift_text(rc.calibration_table(rc.drift_fit(off, PUBLISHED), off, "drift_scale"))
    assert "the simulation orders them" in text and text.count("arm 1 sphere B") >= 3


def test_the_calibration_table_holds_the_grid_medians_and_the_fit(scenario):
    pilot = drift_pilot(1.8)
    fit = rc.drift_fit(pilot, PUBLISHED)
    table = rc.calibration_table(fit, pilot, "drift_scale")
    grid = table[table["point"] == "grid"]
    at = grid[(grid["drift_scale"] == 2.0) & (grid["baseline"] == "before_2A_mm")]
    assert at["median"].item() == pytest.approx(
        pilot.loc[pilot["drift_scale"] == 2.0, "before_2A_mm"].median()
    )
    assert at["trial_spread"].item() == pytest.approx(0.3, rel=0.3)  # the made-up noise
    fitted = table[table["point"] == "joint fit"]
    assert len(grid) == 4 * len(SCALES) and len(fitted) == 4
    assert (fitted["drift_scale"] == rc.fed_value(fit, "drift_scale")).all()
    assert fitted["paper"].tolist() == [before for _, _, before in PAIRS]
    # the fit's spread is the median over the grid of the trials' spread, and met within the
    # baselines' coverage of it
    own = grid.groupby("baseline", sort=False)["trial_spread"].median()
    np.testing.assert_allclose(fitted["spread"], own[fitted["baseline"]].to_numpy())
    assert rc.coverage(table) == Baseline("any", 1.0, 1.0).coverage


def test_the_fed_value_is_the_fit_rounded_to_its_uncertainty(scenario):
    pilot = drift_pilot(1.8)
    fit = rc.drift_fit(pilot, PUBLISHED)
    value = rc.fed_value(fit, "drift_scale")
    assert value == round_to_uncertainty(fit.value, fit.uncertainty)
    decade = 10.0 ** np.floor(np.log10(fit.uncertainty))
    assert value == pytest.approx(round(fit.value / decade) * decade)
    # another machine's last bits give the same value
    nudged = pilot.assign(**{c: pilot[c] * (1 + 1e-13) for c in pilot if c.startswith("before")})
    assert rc.fed_value(rc.drift_fit(nudged, PUBLISHED), "drift_scale") == value


def test_a_fit_at_the_end_of_the_sweep_is_refused(scenario):
    fit = rc.drift_fit(drift_pilot(6.0), PUBLISHED)
    assert fit.at_edge
    with pytest.raises(
        CalibrationError, match=r"drift_scale: the joint fit 3 lies at an end of the swept 1-3"
    ):
        rc.fed_value(fit, "drift_scale")


def test_a_pilot_without_a_pair_or_the_input_is_refused(scenario):
    with pytest.raises(CalibrationError, match=r"no column 'before_2B_mm'"):
        rc.drift_fit(drift_pilot().drop(columns="before_2B_mm"), PUBLISHED)
    with pytest.raises(CalibrationError, match=r"no column 'drift_scale'"):
        rc.drift_fit(drift_pilot().rename(columns={"drift_scale": "s"}), PUBLISHED)
    with pytest.raises(
        CalibrationError, match=r"3 samples cannot give a 95 % interval.*at least 6 needed"
    ):
        rc.drift_fit(drift_pilot(n=3), PUBLISHED)


def test_the_plate_noise_meets_table3_on_a_known_curve(scenario):
    noise = np.exp(np.random.default_rng(2).normal(0.0, 0.2, 30))
    noise /= np.median(noise)
    pilot = pd.DataFrame(
        [
            {
                "plate_sigma_px": s,
                "trial": t,
                "plate_euclid_mm": 0.556 * (s / 0.9) ** 1.5 * noise[t],
            }
            for s in (0.3, 0.6, 1.0, 1.5)
            for t in range(30)
        ]
    )
    fit = rc.plate_fit(pilot, PUBLISHED)
    assert fit.identified
    assert fit.value == pytest.approx(0.9, rel=1e-3)
    own = np.std(np.log(noise), ddof=1)
    assert fit.agreement["tolerance"].item() == pytest.approx(np.expm1(2 * own))
    assert "Table 3's 0.556 mm, met" in rc.plate_text(
        rc.calibration_table(fit, pilot, "plate_sigma_px")
    )


def test_a_small_real_drift_pilot_recovers_the_scale_that_made_its_targets(scenario):
    """The paper's four figures replaced by the pilot's own medians at scale 2 (not on the
    grid the fit reads): the joint fit finds 2 back."""
    rows = run(
        experiments.drift_experiment(n_trials=6, scales=(1.0, 1.5, 2.0, 3.0)),
        3,
        n_jobs=1,
        progress=False,
    )
    at2 = rows[rows["drift_scale"] == 2.0]
    made = [
        [arm, sphere, float(at2[rc.pair_column(arm, sphere)].median()), after]
        for arm, sphere, _, after in PUBLISHED.icp.rows
    ]
    published = PUBLISHED.model_copy(
        update={"icp": PUBLISHED.icp.model_copy(update={"rows": made})}
    )
    fit = rc.drift_fit(rows[rows["drift_scale"] != 2.0], published)
    assert fit.identified
    assert abs(fit.value - 2.0) < 0.15
