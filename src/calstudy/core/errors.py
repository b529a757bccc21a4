"""The one exception every calstudy function raises on bad input."""


class CalibrationError(ValueError):
    """Bad or degenerate input to a calibration step.

    The message names the problem and the number that shows it, for example
    ``"rotation axes of the 6 moves are parallel (condition number 3e+12); add a move about
    another axis"``.
    """


class TooFewTrials(CalibrationError):
    """Too few trials for the interval a verdict needs (of the median, or of a pooled RMS
    ratio): a sweep point with a handful of trials is then written "too few trials"."""


class CalibrationWarning(UserWarning):
    """A result that is returned but should not be trusted without a look: a goodness-of-fit
    test failed (the message says which measurements disagree). Notebooks show it in red."""
