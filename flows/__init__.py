"""Prefect flows: one campaign, and a multi-seed sweep of campaigns.

Importing this package applies noisebo's process defaults for Prefect (``flows.runtime``) before
Prefect itself is imported, so the Python API gets the same temporary-server settings as the
command line."""

from noisebo.flows import runtime

runtime.configure()
