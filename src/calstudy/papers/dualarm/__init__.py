"""The dual-arm coded-marker global calibration paper."""
