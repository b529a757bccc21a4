"""One package per paper: scenario, simulation, experiments, report."""
