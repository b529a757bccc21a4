"""calstudy: a reproducible study of robot-vision calibration on synthetic data."""

from calstudy.core.errors import CalibrationError

__all__ = ["CalibrationError"]
__version__ = "0.1.0"
