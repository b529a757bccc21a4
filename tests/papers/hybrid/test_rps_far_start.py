"""The 3-2-1 penalty method of Eq. 5 from a far start: the printed Eq. 4 (column norms, row
products) is met by matrices that are not rotations, and the penalty sweep finds them."""

import numpy as np
import pandas as pd
import pytest

from calstudy import CalibrationError
from calstudy.core.montecarlo import run
from calstudy.estimators.workpiece import orthogonality
from calstudy.papers.hybrid import experiments, report


def test_eq4_is_met_by_a_matrix_that_is_not_a_rotation():
    # rows orthogonal (R R^T diagonal) with unit columns, but R^T R is not the identity
    c = np.sqrt(0.5)
    q = np.array([[c, -c, 0.0], [c, c, 0.0], [0.0, 0.0, 1.0]])
    r = np.diag(np.sqrt([1.5, 0.5, 1.0])) @ q
    assert np.abs(orthogonality(r)).max() < 1e-15
    assert np.abs(r.T @ r - np.eye(3)).max() == pytest.approx(0.5)


@pytest.fixture(scope="module")
def sweep():
    exp = experiments.rps_penalty_experiment(penalties=(1e-3, 1e3), n_trials=10)
    return pd.DataFrame(run(exp, seed=1, n_jobs=1, progress=False))


def test_the_far_start_finds_non_orthogonal_zeros_of_eq5_and_the_near_ones_do_not(sweep):
    summary = report.summarise_penalty_sweep(sweep)
    far = summary["start"].str.startswith("nominal turned")
    assert (summary.loc[far, "non_orthogonal_share"] > 0).all()
    assert (summary.loc[~far, "non_orthogonal_share"] == 0).all()
    assert (summary.loc[~far, "converged_share"] == 1).all()
    bad = sweep[sweep["converged"].astype(bool) & (sweep["orthogonality_defect"] > 1e-6)]
    assert bad["eq4_residual"].max() < 1e-9  # Eq. 4 holds there
    sentence = report.penalty_far_start_sentence(sweep)
    share = 100.0 * summary.loc[far, "non_orthogonal_share"]
    assert f"{share.min():.3g}" in sentence and "not orthogonal" in sentence
    assert f"{bad['orthogonality_defect'].max():.3g}" in sentence


def test_the_far_start_sentence_needs_a_far_start(sweep):
    near = sweep[~sweep["start"].str.startswith("nominal turned")]
    with pytest.raises(CalibrationError, match="no far start"):
        report.penalty_far_start_sentence(near)
