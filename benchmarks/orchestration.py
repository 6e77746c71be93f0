"""Orchestration overhead: the same campaigns through the Prefect flow and through the pure loop.

    python benchmarks/orchestration.py [--config PATH] [--seeds N] [--policy reward|double|both]

For each campaign it runs the pure core loop (noisebo.campaign.driver.run_campaign) and the campaign
flow (Prefect tasks, journal, an HDF5 snapshot per point) in this process, after a warm-up flow
run that absorbs the temporary Prefect server's start and XLA compilation. It prints, per BO
step: the flow's wall time minus the pure loop's (everything the pipeline adds), and the flow's
wall time minus the core decision time (the issue's definition: includes the simulated
measurements). It also checks that both give the same points. ``--reports both`` (the default)
runs each campaign's flow twice, back to back: without and with its Prefect reports (the run's
name, tags, log lines, progress, summary and table artifacts, status events;
NOISEBO_PREFECT_REPORTS=0 turns them off), so the two columns compare them in one run.

    python benchmarks/orchestration.py --seeds 5 --reports both
"""

from __future__ import annotations

import noisebo.cli  # noqa: F401 - first: one OpenBLAS thread for this process, before numpy loads (as the command line)
import argparse
import os
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]

from noisebo.flows import runtime  # noqa: E402

runtime.configure()

import h5py  # noqa: E402

from noisebo.flows.campaign import campaign  # noqa: E402
from noisebo.flows.local import flow_settings  # noqa: E402
from noisebo.instruments import build  # noqa: E402
from noisebo.campaign.driver import run_campaign  # noqa: E402
from noisebo.config import load_config  # noqa: E402
from noisebo.registry import chosen_policies, policy_names  # noqa: E402


def main(argv=None) -> int:
    with flow_settings():
        return _main(argv)


def _main(argv) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--config", default=str(ROOT / "data" / "configs" / "forrester.yaml"))
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--policy", choices=[*policy_names(), "both", "all"], default="both")
    parser.add_argument(
        "--reports",
        choices=["on", "off", "both"],
        default="both",
        help="the flow runs' Prefect reports (names, logs, artifacts, events)",
    )
    args = parser.parse_args(argv)
    modes = ["off", "on"] if args.reports == "both" else [args.reports]
    base = load_config(args.config)
    policies = chosen_policies(args.policy)
    out = Path(tempfile.mkdtemp(prefix="noisebo-orchestration-"))
    n_steps = base.schedule.n_steps
    started = time.perf_counter()
    campaign(base, seed=10_000, out_dir=str(out / "warmup"), show_progress=False)
    print(f"warm-up flow run (temporary Prefect server start + compilation): {time.perf_counter() - started:.1f} s")
    print(
        "| policy | seed | reports | pure loop (s) | flow (s) | added per BO step (s) | flow minus decisions, per "
        "step (s) | same points |"
    )
    print("|---|---|---|---|---|---|---|---|")
    rows = {mode: [] for mode in modes}
    for policy in policies:
        config = base.with_overrides(acquisition={"policy": policy})
        for seed in range(args.seeds):
            t0 = time.perf_counter()
            pure = run_campaign(config, build(config.instrument), seed)
            t1 = time.perf_counter()
            for mode in modes:
                os.environ["NOISEBO_PREFECT_REPORTS"] = "1" if mode == "on" else "0"
                t2 = time.perf_counter()
                path = campaign(config, seed=seed, out_dir=str(out / mode), show_progress=False)
                t3 = time.perf_counter()
                with h5py.File(path, "r") as f:
                    same = np.array_equal(f["points/value"][()], [p.value for p in pure.state.points])
                    decisions = float(np.sum(f["steps/latency_s"][()]))
                added = (t3 - t2 - (t1 - t0)) / n_steps
                literal = (t3 - t2 - decisions) / n_steps
                rows[mode].append((added, literal, same))
                print(
                    f"| {policy} | {seed} | {mode} | {t1 - t0:.2f} | {t3 - t2:.2f} | {added:.3f} | {literal:.3f} "
                    f"| {same} |",
                    flush=True,
                )
    print()
    for mode in modes:
        added, literal, same = zip(*rows[mode])
        print(
            f"reports {mode}: median added per BO step: {np.median(added):.3f} s; median flow minus decisions per "
            f"step: {np.median(literal):.3f} s; identical points in {sum(same)}/{len(same)} campaigns"
        )
    os.environ.get("KEEP") or __import__("shutil").rmtree(out, ignore_errors=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
