"""Models of the physical world: robots, sensors, optics, targets."""
