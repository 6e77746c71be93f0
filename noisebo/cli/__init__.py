"""The ``noisebo`` command line: an adapter over the flows, storage and views."""
