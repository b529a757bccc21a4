"""Figures of the hybrid study."""

import numpy as np
import pytest

from calstudy import CalibrationError
from calstudy.papers.hybrid import report_figures


def test_fig6_figure_shows_the_named_point_and_rejects_an_unknown_one():
    import matplotlib.pyplot as plt

    d = np.random.default_rng(13).normal(2.0, 0.1, (10, 2, 3))
    fig = report_figures.fig6_figure(d, ["A", "B"], "B")
    lines = fig.axes[0].get_lines()
    np.testing.assert_array_equal(lines[2].get_ydata(), d[:, 1, 2])
    plt.close(fig)
    with pytest.raises(CalibrationError, match="featured point 'H11' is not among the 2"):
        report_figures.fig6_figure(d, ["A", "B"], "H11")
