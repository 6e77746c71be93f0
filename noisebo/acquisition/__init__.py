"""Acquisition: the policies and the proposal of the next (x, t, shots) from a posterior,
within an instrument-time budget. Imports the models, never the campaign."""
