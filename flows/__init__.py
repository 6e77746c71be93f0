"""Prefect flows: one campaign, and a multi-seed sweep of campaigns.

Importing this package sets nothing in the process. ``noisebo.flows.runtime.configure()`` applies
noisebo's process defaults (Prefect's home and quiet settings, JAX's compilation cache): the
command line calls it first thing, and a Python program that wants the same settings calls it
before it imports Prefect."""
