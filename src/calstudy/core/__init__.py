"""Core layer of calstudy: errors, geometry, estimation, statistics, randomness, Monte Carlo."""
