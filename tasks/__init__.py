"""Thin Prefect tasks: each calls one core function or one adapter and sets its policy."""
