"""A sweep's wall time sequential, on 2 threads, on a 2-worker local Dask cluster and on 2 Prefect
workers of one process work pool, against a real loopback Prefect server started for the run;
and whether every seed's campaign equals the seed run alone.

    python benchmarks/sweeps.py [--config PATH] [--seeds 0-3] [--policy both] [--json PATH]

Each engine writes its own folder; a campaign counts as equal when its points (x, t, value),
predicted optimal t per step and final t_opt equal those of ``run_campaign`` for that seed.
The config is validated as ``noisebo run`` validates it before any server starts (``_config.py``).
"""

from __future__ import annotations

import noisebo.cli  # noqa: F401 - first: one OpenBLAS thread for this process, before numpy loads (as the command line)
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))  # the shared helpers (_config, _tstar)

from _config import Parser, benchmark_config  # noqa: E402

from noisebo.cli.common import parse_seeds  # noqa: E402
from noisebo.flows.processes import BIN, local_server, start, stop, wait_for  # noqa: E402
from noisebo.instruments import build  # noqa: E402
from noisebo.campaign.driver import run_campaign  # noqa: E402
from noisebo.registry import chosen_policies, policy_names  # noqa: E402
from noisebo.storage.record import read_record  # noqa: E402

ENGINES = {
    "sequential (1 thread)": ["--runner", "threads", "--workers", "1"],
    "2 threads": ["--runner", "threads", "--workers", "2"],
    "Dask, 2 local workers": ["--runner", "dask", "--workers", "2"],
    "2 Prefect workers": ["--runner", "workers"],
}


def equal_to_alone(config, seeds, policies, folder: Path) -> tuple[int, int]:
    """(campaigns equal to the seed run alone, campaigns checked)."""
    same = total = 0
    for policy in policies:
        cfg = config.with_overrides(acquisition={"policy": policy})
        for seed in seeds:
            alone = run_campaign(cfg, build(cfg.instrument), seed)
            data = read_record(folder / f"{cfg.name}_{policy}_s{seed:04d}.h5")
            p = data.points
            same += bool(
                np.array_equal(p.x, [q.x for q in alone.state.points])
                and np.array_equal(p.t, [q.t for q in alone.state.points])
                and np.array_equal(p.value, [q.value for q in alone.state.points])
                and np.array_equal(data.steps.t_opt, [d.t_opt for d in alone.decisions])
                and data.summary.t_opt == alone.summary.t_opt
            )
            total += 1
    return same, total


def main(argv=None) -> int:
    parser = Parser(prog=Path(__file__).name, description=__doc__.split("\n")[0])
    parser.add_argument("--config", default=str(ROOT / "data" / "configs" / "forrester.yaml"))
    parser.add_argument("--seeds", default="0-3")
    parser.add_argument("--policy", choices=[*policy_names(), "both", "all"], default="both")
    parser.add_argument("--json", type=Path, default=None)
    args = parser.parse_args(argv)
    config, _ = benchmark_config(parser, args.config)
    seeds = parse_seeds(args.seeds)
    policies = chosen_policies(args.policy)
    n = len(seeds) * len(policies)
    rows = []
    with tempfile.TemporaryDirectory(prefix="noisebo-sweeps-") as tmp, local_server(Path(tmp) / "server") as env:
        tmp = Path(tmp)
        deployed = subprocess.run(
            [str(BIN / "noisebo"), "deploy", args.config, "--pool", "bench", "--out", str(tmp / "unused")],
            env=env,
            capture_output=True,
            text=True,
        )
        if deployed.returncode:
            raise SystemExit(deployed.stdout + deployed.stderr)
        for name, options in ENGINES.items():
            folder = tmp / name.replace(" ", "_").replace(",", "")
            workers = []
            if "--runner" in options and options[options.index("--runner") + 1] == "workers":
                logs = [tmp / f"worker{i}.log" for i in (1, 2)]
                workers = [
                    start([str(BIN / "prefect"), "worker", "start", "--pool", "bench", "--limit", "1"], env, log)
                    for log in logs
                ]
                wait_for(lambda logs=logs: all("started" in log.read_text() for log in logs), 120, "two workers", logs)
            started = time.perf_counter()
            done = subprocess.run(
                [
                    str(BIN / "noisebo"),
                    "sweep",
                    args.config,
                    "--seeds",
                    args.seeds,
                    "--policy",
                    args.policy,
                    "--out",
                    str(folder),
                    *options,
                ],
                env=env,
                capture_output=True,
                text=True,
            )
            wall = time.perf_counter() - started
            for worker in workers:
                stop(worker)
            if done.returncode:
                raise SystemExit(f"{name}: sweep failed\n{done.stdout[-2000:]}\n{done.stderr[-2000:]}")
            same, total = equal_to_alone(config, seeds, policies, folder)
            rows.append({"engine": name, "campaigns": n, "wall_s": wall, "equal_to_alone": same})
            print(
                f"{name:>24}: {n} campaigns in {wall:6.1f} s, {same}/{total} equal to the seed run alone",
                file=sys.stderr,
                flush=True,
            )
    base = rows[0]["wall_s"]
    print(
        f"\n{config.name}: seeds {args.seeds} x {policies} ({n} campaigns), wall time including each command's start-up"
    )
    print("| engine | wall time (s) | vs sequential | campaigns equal to the seed alone |\n|---|---|---|---|")
    for r in rows:
        print(
            f"| {r['engine']} | {r['wall_s']:.1f} | {r['wall_s'] / base:.2f} | {r['equal_to_alone']}/{r['campaigns']} |"
        )
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
