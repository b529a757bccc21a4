"""Models of the physical world: robots, sensors (pinhole camera, stereo rig, line laser),
optics, targets."""
