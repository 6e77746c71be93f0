"""The sweep flow: one campaign per (seed, policy), run in parallel by a Prefect task runner,
then a summary table of the benchmark figures over the campaigns' HDF5 files.

Re-running a sweep into the same directory continues it: a finished campaign is left as it is,
an interrupted one is resumed, a missing one is started.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Literal

import httpx
from prefect import flow, task
from prefect.cache_policies import NO_CACHE
from prefect.exceptions import PrefectHTTPStatusError
from prefect.task_runners import ThreadPoolTaskRunner

from flows.campaign import campaign, campaign_path, resolve_config, resume
from instruments import build
from noisebo.config import CampaignConfig
from noisebo.metrics import campaign_figures, summarise_campaigns, summary_table
from noisebo.storage.hdf5 import read_campaign


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


def figures_from_file(path: str | Path) -> dict:
    """Benchmark figures of one finished campaign, from its HDF5 file alone."""
    data = read_campaign(path)
    config = resolve_config(CampaignConfig.model_validate(data["attrs"]["config"]), None)
    if data["summary"] is None:
        raise ValueError(f"{path}: campaign not finished (status {data['attrs']['status']})")
    record = campaign_figures(
        config, build(config.instrument), data["steps"]["t_opt"], data["summary"]["t_opt"], data["grid"]["x"],
        data["summary"]["f_mean"], data["shots"]["t"], data["steps"]["latency_s"],
    )
    record.update(seed=int(data["attrs"]["seed"]), file=str(path))
    return record


def write_summary(paths: list[str], out_dir: str | Path) -> Path:
    """sweep_summary.md (a table per policy) and sweep_summary.json (one record per campaign)."""
    records = [figures_from_file(p) for p in paths]
    policies = sorted({r["policy"] for r in records})
    rows = {p: summarise_campaigns([r for r in records if r["policy"] == p]) for p in policies}
    out = Path(out_dir)
    (out / "sweep_summary.json").write_text(json.dumps({"records": records, "summary": rows}, indent=1))
    table = out / "sweep_summary.md"
    table.write_text("Median [IQR] over campaigns.\n\n" + summary_table(rows) + "\n")
    return table


@flow(name="sweep", task_runner=ThreadPoolTaskRunner(max_workers=2))
def sweep(
    config: str | CampaignConfig = "data/configs/forrester.yaml",
    seeds: list[int] = [0, 1, 2, 3],  # noqa: B006 - Prefect parameters are validated copies
    policies: list[Literal["reward", "double"]] = ["reward", "double"],  # noqa: B006
    out_dir: str = "data/runs/sweep",
) -> str:
    """Run every (seed, policy) campaign and return the path of the summary table."""
    base = resolve_config(config, None)
    Path(out_dir).mkdir(parents=True, exist_ok=True)
    futures = [
        sweep_campaign.submit(base.with_overrides(acquisition={"policy": policy}), seed, out_dir)
        for policy in policies
        for seed in seeds
    ]
    paths, failures = [], []
    for future in futures:
        outcome = future.result(raise_on_failure=False)
        if isinstance(outcome, BaseException):
            failures.append(f"{type(outcome).__name__}: {outcome}")
        else:
            paths.append(outcome)
    table = write_summary(paths, out_dir) if paths else None
    if failures:
        raise SweepError(f"{len(failures)} of {len(futures)} campaigns failed (summary of the rest: {table}): "
                         + "; ".join(failures))
    return str(table)


class SweepError(RuntimeError):
    """Some campaigns of a sweep failed; the others finished and are summarised."""
