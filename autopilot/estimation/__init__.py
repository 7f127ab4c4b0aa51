"""State estimation: the EKF on the IMU, its aiding sensors, attitude arithmetic, terrain."""
