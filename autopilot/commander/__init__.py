"""The commander: flight phases and modes, what a ground station may ask, failsafes, guided and
offboard control, mission items."""
