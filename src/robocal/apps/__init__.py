"""Applications built on robocal's public API (the GUI)."""
