"""Screenshot of the Prefect UI's flow-runs list after a sweep, for the documentation (docs/prefect.md).

    python benchmarks/screenshot_sweep_runs.py [--config PATH] [--seeds 0-1] [--policy both] [--out PATH]

Needs headless Chromium (Debian: ``apt-get install -y chromium``). Like ``screenshot_flow_run.py``
(whose functions it uses) it starts a Prefect server (UI on) on a free loopback port with its own
PREFECT_HOME in a temporary folder, then runs a small sweep against it (``noisebo sweep CONFIG
--seeds 0-1 --policy both --workers 2``: four campaigns, files in the same temporary folder), finds
the sweep's flow run and its campaigns' flow runs (its subflow runs) through Prefect's API, and
takes a PNG of the V2 UI's runs list, ``/v2/runs``, at 1600x1300 (taller than the flow run's
page: the list comes below a chart of the runs): the sweep's run (``sweep-NAME-sFIRST-LAST``) and
its campaigns (``NAME-POLICY-sSEED``), each with its state, tags and task runs.

Before the screenshot it loads the page with ``--dump-dom`` and checks that the list shows the
name of every one of those runs (the API's names), waiting longer (Chromium's virtual time) if not,
and it refuses an image of (nearly) one colour. Images over 400 KB are scaled down. The server,
the sweep and Chromium are stopped at the end, however the script ends (SIGTERM included).
"""

from __future__ import annotations

import noisebo.cli  # noqa: F401 - first: one OpenBLAS thread for this process, before numpy loads (as the command line)
import argparse
import signal
import sys
import tempfile
import time
from pathlib import Path

from headless_chromium import ChromiumMissing, find_chromium
from screenshot_flow_run import ROOT, Api, on_sigterm, run_noisebo, screenshot

from noisebo.flows.processes import local_server, wait_for

FINAL = ("COMPLETED", "FAILED", "CRASHED", "CANCELLED")
WINDOW = (1600, 1300)  # the list of five runs fits below the runs chart


def parse_args(argv=None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--config", default="data/configs/forrester.yaml", help="campaign YAML (default: %(default)s)")
    parser.add_argument("--seeds", default="0-1", help="the sweep's seeds: N, A-B or A,B,C (default: %(default)s)")
    parser.add_argument("--policy", default="both", help="as noisebo sweep's --policy (default: %(default)s)")
    parser.add_argument("--out", type=Path, default=ROOT / "docs" / "images" / "prefect-sweep-runs.png")
    parser.add_argument(
        "--budget-ms",
        type=int,
        default=20_000,
        help="Chromium's virtual time budget for the page to render; doubled (twice) "
        "if the page is not rendered yet (default: %(default)s)",
    )
    return parser.parse_args(argv)


def run_sweep(env: dict, args: argparse.Namespace, folder: Path) -> None:
    run_noisebo(
        env,
        ["sweep", args.config, "--seeds", args.seeds, "--policy", args.policy, "--workers", "2"]
        + ["--out", str(folder / "sweep")],
        "sweep",
        timeout_s=1200,
    )


def sweep_runs(api: Api) -> tuple[dict, list[dict]]:
    """The newest sweep's flow run and its campaigns' flow runs, once all are final."""
    sweeps = api.post("flow_runs/filter", {"flows": {"name": {"any_": ["sweep"]}}, "sort": "START_TIME_DESC"})
    if not sweeps:
        raise SystemExit("screenshot_sweep_runs: the server has no sweep flow run")
    sweep_id = sweeps[0]["id"]
    body = {"flow_runs": {"parent_flow_run_id": {"any_": [sweep_id]}}, "sort": "NAME_ASC", "limit": 200}
    wait_for(
        lambda: (
            api.flow_run(sweep_id)["state_type"] in FINAL
            and all(run["state_type"] in FINAL for run in api.post("flow_runs/filter", body))
        ),
        60,
        "the sweep's flow runs' final states",
    )
    return api.flow_run(sweep_id), api.post("flow_runs/filter", body)


def main(argv=None) -> int:
    args = parse_args(argv)
    try:
        chromium = find_chromium()
    except ChromiumMissing as error:
        raise SystemExit(f"screenshot_sweep_runs: {error}") from None
    signal.signal(signal.SIGTERM, on_sigterm)
    with tempfile.TemporaryDirectory(prefix="noisebo-screenshot-") as tmp:
        folder = Path(tmp)
        started = time.monotonic()
        with local_server(folder / "prefect") as env:
            env.pop("NOISEBO_PREFECT_REPORTS", None)
            base = env["PREFECT_API_URL"].removesuffix("/api")
            print(f"Prefect server: {base}, up in {time.monotonic() - started:.1f} s", flush=True)
            run_sweep(env, args, folder)
            api = Api(env["PREFECT_API_URL"])
            sweep, campaigns = sweep_runs(api)
            print(f"sweep run: {sweep['name']} ({sweep['state_name']})", flush=True)
            for run in campaigns:
                print(f"  campaign run: {run['name']} ({run['state_name']})", flush=True)
            if not campaigns:
                raise SystemExit("screenshot_sweep_runs: the sweep's flow run has no campaign flow runs")
            url = f"{base}/v2/runs"
            names = [sweep["name"], *(run["name"] for run in campaigns)]
            print(f"screenshot of {url}", flush=True)
            profile = folder / "chromium-profile"
            written = screenshot(chromium, profile, url, names, [], args.budget_ms, args.out, WINDOW)
        print("server stopped", flush=True)
    print(written.relative_to(ROOT) if written.is_relative_to(ROOT) else written)
    return 0


if __name__ == "__main__":
    sys.exit(main())
