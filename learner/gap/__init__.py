"""Sim-to-real gap diagnosis: residual forces of flight logs against a nominal simulator world,
where they are significant, which catalogue effects explain them, and how far a corrected world
closes the gap (DESIGN.md, "Sim-to-real gap diagnosis")."""
