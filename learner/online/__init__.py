"""Online learning: update rules, guards and weight snapshots (pure; no threads)."""
