"""calstudy: a reproducible study of robot-vision calibration on synthetic data."""

from calstudy.core.errors import CalibrationError, CalibrationWarning

__all__ = ["CalibrationError", "CalibrationWarning"]
__version__ = "0.1.0"
