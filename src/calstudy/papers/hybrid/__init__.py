"""The hybrid inspection station paper."""
