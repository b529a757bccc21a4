"""The binocular hand-eye correction paper."""
