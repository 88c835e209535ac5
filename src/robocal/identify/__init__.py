"""Step 3 of a calibration — what the parameters really are: observability and identification."""
