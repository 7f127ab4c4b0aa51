"""The autopilot: commander, navigator, controller, mixer, ground-station endpoint."""
