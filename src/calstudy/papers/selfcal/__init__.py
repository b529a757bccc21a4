"""The one-step self-calibration paper."""
