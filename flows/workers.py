"""Campaigns as deployments of a Prefect ``process`` work pool, run by however many
``prefect worker start --pool POOL`` processes there are, and sweeps that hand each campaign to
them (``noisebo deploy`` and ``noisebo sweep --runner workers``)."""

from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

from prefect import flow

from noisebo.config import load_config
from noisebo.flows.runtime import PROJECT_ROOT

if TYPE_CHECKING:
    from prefect import Flow


def ensure_process_pool(pool: str) -> None:
    """Create the process work pool ``pool`` unless it exists."""
    from prefect.client.orchestration import get_client
    from prefect.client.schemas.actions import WorkPoolCreate
    from prefect.exceptions import ObjectAlreadyExists

    with get_client(sync_client=True) as client:
        try:
            client.create_work_pool(WorkPoolCreate(name=pool, type="process"))
        except ObjectAlreadyExists:
            pass


def deploy_campaign(config_path: str | Path, pool: str, out_dir: str | Path) -> str:
    """Register ``campaign/NAME`` (NAME: the config's name) in the process work pool ``pool``,
    its code taken from this checkout; returns the deployment's full name. Each run triggered by
    hand writes a folder of its own under ``out_dir`` (a sweep's runs write into the sweep's)."""
    config_path = str(Path(config_path).resolve())
    name = load_config(config_path).name
    ensure_process_pool(pool)
    deploy_from_checkout(
        "flows/campaign.py:campaign",
        name,
        pool,
        {"config": config_path, "out_dir": str(Path(out_dir).resolve()), "show_progress": False, "per_run_dir": True},
        description=f"one {name} campaign on the {pool} work pool; pass seed (and policy)",
        tags=["noisebo", name],
    )
    return f"campaign/{name}"


def deploy_from_checkout(entrypoint: str, name: str, pool: str, parameters: dict, description: str, tags: list) -> None:
    """Register the flow at ``entrypoint`` of this checkout as the deployment ``name`` of ``pool``."""
    # called from sync code, Prefect's dispatcher returns the flow itself rather than a coroutine
    source = cast("Flow[..., Any]", flow.from_source(source=str(PROJECT_ROOT), entrypoint=entrypoint))
    source.deploy(
        name=name,
        work_pool_name=pool,
        build=False,
        push=False,
        print_next_steps=False,
        parameters=parameters,
        description=description,
        tags=tags,
    )
