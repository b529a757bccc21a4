"""Core layer: errors, geometry, estimation, statistics and the verdict rule; no paper in it."""
