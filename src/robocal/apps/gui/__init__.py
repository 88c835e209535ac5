"""``robocal gui``: the model builder and the calibration in a browser window (Dash, offline)."""
