"""calstudy: a reproducible study of robot-vision calibration on synthetic data."""

from .errors import CalibrationError

__all__ = ["CalibrationError"]
__version__ = "0.1.0"
