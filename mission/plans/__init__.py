"""Mission files: one mission model in YAML, QGroundControl .plan and QGC WPL 110."""
