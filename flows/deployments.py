"""Prefect deployments of the campaign and sweep flows, served by one long-running process.

For a config named NAME (its ``name`` field) it declares:
    campaign/NAME   one campaign; parameters seed, policy, out_dir, record_rrd (config fixed), each
                    run in a folder of its own: out_dir/NAME-POLICY-sSEED-<start, UTC>-<run id>/
    sweep/NAME      seeds x policies into out_dir/sweep-NAME/<scheduled start, UTC>/, on a cron
                    or interval schedule if one is given (otherwise run on demand)

``noisebo serve CONFIG [CONFIG ...]`` registers them with the Prefect server that
PREFECT_API_URL names and runs what is triggered, e.g.
``prefect deployment run 'campaign/forrester' --param seed=3``.
"""

from __future__ import annotations

from datetime import timedelta
from pathlib import Path

from prefect import serve

from noisebo.flows.campaign import campaign
from noisebo.flows.sweep import sweep
from noisebo.config import load_config


def deployments_for(
    config_path: str | Path,
    out_dir: str | Path,
    sweep_seeds: list[int],
    sweep_policies: list[str],
    cron: str | None = None,
    interval_s: float | None = None,
) -> list:
    """The campaign and sweep deployments of one config file (validated here, once)."""
    config_path = str(Path(config_path).resolve())
    name = load_config(config_path).name
    out_dir = str(Path(out_dir).resolve())
    schedule = {"cron": cron} if cron else ({"interval": timedelta(seconds=interval_s)} if interval_s else {})
    return [
        campaign.to_deployment(
            name=name,
            parameters={"config": config_path, "out_dir": out_dir, "show_progress": True, "per_run_dir": True},
            description=f"one {name} campaign; pass seed (and policy) as parameters",
            tags=["noisebo", name],
        ),
        sweep.to_deployment(
            name=name,
            parameters={
                "config": config_path,
                "seeds": sweep_seeds,
                "policies": sweep_policies,
                "out_dir": str(Path(out_dir) / f"sweep-{name}"),
                "per_run_dir": True,
            },
            description=f"{name} campaigns over seeds x policies, then the sweep summary and figure",
            tags=["noisebo", name, "sweep"],
            **schedule,
        ),
    ]


def serve_all(deployments: list, limit: int | None = None) -> None:
    """Register ``deployments`` and run their flow runs in this process until interrupted."""
    serve(*deployments, limit=limit)
