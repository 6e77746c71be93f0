"""Prefect flows: one campaign, and a multi-seed sweep of campaigns."""
