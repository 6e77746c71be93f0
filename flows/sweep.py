"""The sweep flow: one campaign per (seed, policy), run in parallel by a Prefect task runner,
then a summary table of the benchmark figures over the campaigns' HDF5 files.

Re-running a sweep into the same directory continues it: a finished campaign is left as it is,
an interrupted one is resumed, a missing one is started.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Literal, cast

import httpx
from prefect import flow, task
from prefect.cache_policies import NO_CACHE
from prefect.exceptions import PrefectHTTPStatusError
from prefect.task_runners import ThreadPoolTaskRunner

from noisebo.flows.campaign import DEFAULT_CONFIG, campaign, campaign_path, resolve_config, resume
from noisebo.flows.reporting import report_sweep, run_name
from noisebo.config import CampaignConfig
from noisebo.view.report import write_summary

if TYPE_CHECKING:
    from prefect.client.schemas.objects import FlowRun


def _orchestration_failed(task, task_run, state) -> bool:
    """Retry a campaign whose Prefect API call failed (the temporary server answers 503 under
    load): its journal makes the retry a resume, so nothing is measured twice."""
    try:
        state.result()
    except (PrefectHTTPStatusError, httpx.HTTPError):
        return True
    except Exception:  # noqa: BLE001 - anything else is a real failure
        return False
    return False


@task(
    name="sweep-campaign",
    cache_policy=NO_CACHE,
    retries=3,
    retry_delay_seconds=2,
    retry_condition_fn=_orchestration_failed,
)
def sweep_campaign(config: CampaignConfig, seed: int, out_dir: str) -> str:
    path = campaign_path(config, seed, out_dir)
    if path.exists():
        done = resume(str(path), show_progress=False)
    else:
        done = campaign(config, seed=seed, out_dir=out_dir, show_progress=False)
    print(f"finished {done}", flush=True)
    return done


@task(name="sweep-campaign-on-workers", cache_policy=NO_CACHE)
def campaign_on_workers(deployment: str, config: CampaignConfig, seed: int, out_dir: str) -> str:
    """Hand one campaign to the workers of ``deployment``'s work pool and wait for it."""
    from prefect.deployments import run_deployment

    from prefect.runtime import flow_run

    policy = config.acquisition.policy
    # One flow run per campaign even when a loaded server makes the client repeat its request.
    key = f"{flow_run.id}:{deployment}:{policy}:{seed}"
    # called from sync code, Prefect's dispatcher returns the flow run itself rather than a coroutine
    parameters = {"seed": seed, "policy": policy, "out_dir": out_dir, "per_run_dir": False}
    name = run_name(config.name, policy, seed)  # named as it is created, not renamed as it starts
    run = cast(
        "FlowRun",
        run_deployment(deployment, parameters=parameters, timeout=None, idempotency_key=key, flow_run_name=name),
    )
    state = run.state
    if state is None or not state.is_completed():
        ended = f"{state.name}: {state.message}" if state is not None else "with no state"
        raise RuntimeError(f"{deployment} seed {seed} ({policy}) ended {ended}")
    return str(campaign_path(config, seed, out_dir))


# Prefect types task_runner as TaskRunner[PrefectFuture[Any]], invariant in the future type, which no
# ThreadPoolTaskRunner (TaskRunner[PrefectConcurrentFuture]) matches; Prefect's own examples pass one.
def _sweep_run_name() -> str:
    from prefect.runtime import flow_run

    from noisebo.flows.reporting import sweep_run_name

    return sweep_run_name(flow_run.parameters, DEFAULT_CONFIG)


@flow(name="sweep", flow_run_name=_sweep_run_name, task_runner=ThreadPoolTaskRunner(max_workers=2))  # type: ignore[arg-type]
def sweep(
    config: str | CampaignConfig = DEFAULT_CONFIG,
    seeds: list[int] = [0, 1, 2, 3],  # noqa: B006 - Prefect parameters are validated copies
    policies: list[str] | None = None,
    out_dir: str = "data/runs/sweep",
    per_run_dir: bool = False,
    deployment: str | None = None,
) -> str:
    """Run every (seed, policy) campaign and return the path of the summary table. ``policies``:
    names of installed policies (``noisebo policies``; None: the paper's two, as the registry says).
    ``per_run_dir``: write into OUT_DIR/<scheduled start, UTC> so that scheduled runs of a
    deployment each get their own sweep instead of resuming the last one. ``deployment`` (e.g.
    "campaign/forrester", see ``noisebo deploy``): run every campaign as a run of that deployment,
    on the workers of its work pool, instead of in this process's task runner."""
    base = resolve_config(config, None)
    if per_run_dir:
        from datetime import timezone

        from prefect.runtime import flow_run

        started = flow_run.scheduled_start_time.astimezone(timezone.utc)
        out_dir = str(Path(out_dir) / started.strftime("%Y%m%dT%H%M%SZ"))
    Path(out_dir).mkdir(parents=True, exist_ok=True)
    if policies is None:
        from noisebo.registry import paper_policies

        policies = list(paper_policies())
    configs = [(base.with_overrides(acquisition={"policy": policy}), seed) for policy in policies for seed in seeds]
    if deployment:
        out_dir = str(Path(out_dir).resolve())
        futures = [campaign_on_workers.submit(deployment, cfg, seed, out_dir) for cfg, seed in configs]
    else:
        futures = [sweep_campaign.submit(cfg, seed, out_dir) for cfg, seed in configs]
    paths: list[str] = []
    failures: list[str] = []
    for future in futures:
        outcome = future.result(raise_on_failure=False)
        if isinstance(outcome, BaseException):
            failures.append(f"{type(outcome).__name__}: {outcome}")
        else:
            paths.append(outcome)
    table = write_summary(paths, out_dir)[0] if paths else None
    report_sweep(base.name, table, out_dir, len(futures), failures)
    if failures:
        raise SweepError(
            f"{len(failures)} of {len(futures)} campaigns failed (summary of the rest: {table}): " + "; ".join(failures)
        )
    return str(table)


def task_runner(kind: Literal["threads", "dask"] = "threads", workers: int = 2, address: str | None = None):
    """The sweep's task runner: ``workers`` threads in this process, or Dask: the cluster at
    ``address`` (e.g. tcp://10.0.0.5:8786) or a local cluster of ``workers`` single-threaded
    worker processes. Dask starts its worker processes with spawn, never fork, so no process
    inherits a JAX runtime. Campaigns in other processes report to the Prefect server that
    PREFECT_API_URL names (without one, each worker process starts a temporary server)."""
    if kind == "threads":
        return ThreadPoolTaskRunner(max_workers=workers)
    from prefect_dask import DaskTaskRunner

    if address:
        return DaskTaskRunner(address=address)
    return DaskTaskRunner(
        cluster_kwargs={"n_workers": workers, "threads_per_worker": 1, "processes": True, "dashboard_address": None}
    )


class SweepError(RuntimeError):
    """Some campaigns of a sweep failed; the others finished and are summarised."""
