"""The simulated vehicle: parameters, PyBullet world, physical effects, the HIL link."""
