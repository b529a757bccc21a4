"""Shared mathematics: errors, geometry, estimation, statistics, paths."""
