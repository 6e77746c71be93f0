"""Durable campaign records: an append-only journal (the source of truth) and the HDF5 file
derived from it."""
