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

import asyncio
import signal
from datetime import timedelta
from pathlib import Path

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
    """Register ``deployments`` and run their flow runs in this process until SIGINT or SIGTERM;
    then stop at once: flow runs under way are cancelled (as Prefect's runner does), the
    deployments' schedules paused, and the runs they had scheduled and not started deleted, so
    that none is left "late" in the UI."""
    asyncio.run(_serve(deployments, limit))


async def _serve(deployments: list, limit: int | None) -> None:
    from prefect.runner import Runner

    runner = Runner(pause_on_shutdown=True, limit=limit)
    ids = [await runner.aadd_deployment(d) for d in deployments]
    stop = asyncio.Event()
    serving = asyncio.create_task(runner.start())
    while not runner.started and not serving.done():  # its start sets its own SIGTERM handler
        await asyncio.sleep(0.05)
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, stop.set)
    await asyncio.wait([serving, asyncio.create_task(stop.wait())], return_when=asyncio.FIRST_COMPLETED)
    if runner.started:
        await runner.astop()
    await serving  # pauses the schedules on its way out
    await delete_scheduled_runs(ids)


async def delete_scheduled_runs(deployment_ids: list) -> int:
    """Delete the flow runs of these deployments that are scheduled and not started; how many."""
    from prefect import get_client
    from prefect.client.schemas.filters import (
        DeploymentFilter,
        DeploymentFilterId,
        FlowRunFilter,
        FlowRunFilterState,
        FlowRunFilterStateType,
    )
    from prefect.client.schemas.objects import StateType

    async with get_client() as client:
        runs = await client.read_flow_runs(
            deployment_filter=DeploymentFilter(id=DeploymentFilterId(any_=deployment_ids)),
            flow_run_filter=FlowRunFilter(
                state=FlowRunFilterState(type=FlowRunFilterStateType(any_=[StateType.SCHEDULED]))
            ),
        )
        for run in runs:
            await client.delete_flow_run(run.id)
    return len(runs)
