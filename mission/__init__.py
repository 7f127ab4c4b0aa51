"""Missions and the groundfx command line."""
