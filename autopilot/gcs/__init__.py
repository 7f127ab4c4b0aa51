"""The ground-station endpoint: the MAVLink link, signing, telemetry, the parameter and mission
protocols."""
