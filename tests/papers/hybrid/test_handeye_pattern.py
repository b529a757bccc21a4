"""The pure translations of the sphere hand-eye on a designed pattern against random draws."""

from dataclasses import replace

import numpy as np
import pandas as pd
import pytest

from calstudy import CalibrationError
from calstudy.papers.hybrid import report_sweeps
from calstudy.papers.hybrid.handeye_experiments import SCENARIOS
from calstudy.papers.hybrid.simulate import DESIGNED_SHIFTS, make_station


def _flange_positions(station, seed):
    q_t, _ = station.sphere_moves(4, 6, np.random.default_rng(seed))
    return np.array([station.nominal.fk(q)[:3, 3] for q in q_t])


def test_designed_translations_do_not_depend_on_the_draw_and_span_three_directions():
    station = make_station(np.random.default_rng(0), **SCENARIOS["sensor noise only"])
    designed = replace(station, translation_pattern="designed")
    a, b = _flange_positions(designed, 1), _flange_positions(designed, 2)
    np.testing.assert_allclose(a, b, atol=1e-6)
    steps = a[1:] - a[0]
    assert np.linalg.matrix_rank(steps, tol=1e-3) == 3
    random = _flange_positions(station, 1) - _flange_positions(station, 2)
    assert np.abs(random).max() > 1.0
    assert DESIGNED_SHIFTS.shape[1] == 3
    with pytest.raises(CalibrationError, match="translation pattern 'grid'"):
        replace(station, translation_pattern="grid").sphere_moves(4, 6, np.random.default_rng(1))


def test_the_pattern_sentence_states_both_rows():
    summary = pd.DataFrame(
        {
            "translation_pattern": ["designed", "random"],
            "median_ratio": [4.6, 4.1],
            "ci_low": [3.6, np.nan],
            "ci_high": [6.0, np.nan],
            "p95_ratio": [9.8, 21.1],
            "verdict": ["not reproduced", "too few trials"],
        }
    )
    sentence = report_sweeps.pattern_sentence(summary)
    assert "designed pattern (each move along a new direction, the full ranges)" in sentence
    assert "4.6 (3.6-6), 95th percentile 9.8, not reproduced" in sentence
    assert "drawn at random: median ratio 4.1, 95th percentile 21.1, too few trials" in sentence
    with pytest.raises(CalibrationError, match=r"lacks \['random'\]"):
        report_sweeps.pattern_sentence(summary.iloc[:1])
