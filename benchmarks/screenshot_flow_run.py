"""Screenshots of a campaign's flow run page in the Prefect UI, for the documentation (docs/prefect.md).

    python benchmarks/screenshot_flow_run.py [--config PATH] [--seed N] [--out DIR] [--only-logs]

Needs headless Chromium (Debian: ``apt-get install -y chromium``). It starts a Prefect server
(``prefect server start``, UI on) on a free loopback port with its own PREFECT_HOME in a temporary
folder, runs one campaign against it (``noisebo run CONFIG --seed N --no-rrd``, files in the same
temporary folder), finds the flow run through Prefect's API (the newest top-level run: the server
is new) and takes three PNG screenshots of its page, ``/v2/runs/flow-run/ID``, at 1600x1000 (the V2 UI,
where Prefect 3.8's UI opens by default; the V1 UI, ``/runs/flow-run/ID``, draws its run graph
without the task names in headless Chromium, and is not shot here):

- ``DIR/prefect-flow-run.png``: the Logs tab (the run's name, tags and state, its task runs as
  Prefect's graph, and its first log lines);
- ``DIR/prefect-flow-run-tasks.png``: the Task Runs tab (the task runs as a list, readable however
  many there are: the graph squeezes them into its fixed height);
- ``DIR/prefect-flow-run-artifacts.png``: the Artifacts tab (the progress, summary and points
  artifacts).

Nothing here names a task: before each screenshot it loads the same page with ``--dump-dom`` and
checks that the UI has rendered what the API says the run has (its name, its number of task runs,
its first log line; one of its task runs' names; the artifacts' keys), waiting longer (Chromium's
virtual time) if not, and it refuses an image of (nearly) one colour. Images over 400 KB are scaled down. The server, the
campaign and Chromium are stopped at the end, however the script ends (SIGTERM included).
"""

from __future__ import annotations

import noisebo.cli  # noqa: F401 - first: one OpenBLAS thread for this process, before numpy loads (as the command line)
import argparse
import html
import io
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import headless_chromium
import httpx
from headless_chromium import ChromiumMissing, find_chromium, stop_group
from PIL import Image

from noisebo.flows.processes import local_server, wait_for

ROOT = Path(__file__).resolve().parents[1]

WINDOW = (1600, 1000)
MAX_BYTES = 400_000


def parse_args(argv=None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--config", default="data/configs/forrester.yaml", help="campaign YAML (default: %(default)s)")
    parser.add_argument("--seed", type=int, default=3)
    parser.add_argument("--out", type=Path, default=ROOT / "docs" / "images", help="folder of the PNGs")
    parser.add_argument(
        "--budget-ms",
        type=int,
        default=20_000,
        help="Chromium's virtual time budget for the page to render; doubled (twice) "
        "if the page is not rendered yet (default: %(default)s)",
    )
    parser.add_argument(
        "--only-logs",
        action="store_true",
        help="only the flow run page's Logs tab, not its Task Runs and Artifacts tabs",
    )
    return parser.parse_args(argv)


def run_campaign(env: dict, config: str, seed: int, folder: Path, rrd: bool = False) -> None:
    """``noisebo run CONFIG --seed SEED`` into ``folder/runs`` (with its Rerun recording if ``rrd``);
    exits with the campaign's output if it fails."""
    args = ["run", config, "--seed", str(seed), "--out", str(folder / "runs")] + ([] if rrd else ["--no-rrd"])
    run_noisebo(env, args, "campaign", timeout_s=600)


def run_noisebo(env: dict, args: list[str], what: str, timeout_s: float) -> None:
    """``noisebo ARGS`` in its own process group (stopped however this ends); exits naming ``what``
    with its output if it fails, else says how long it took and its last lines."""
    command = [sys.executable, "-m", "noisebo.cli.main", *args]
    print(f"{what}:", "noisebo", *args, flush=True)
    started = time.monotonic()
    process = subprocess.Popen(
        command, env=env, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, start_new_session=True
    )
    try:
        output, _ = process.communicate(timeout=timeout_s)
    finally:
        stop_group(process)
    if process.returncode != 0:
        raise SystemExit(
            f"{Path(sys.argv[0]).stem}: the {what} failed (exit code {process.returncode}):\n{output[-3000:]}"
        )
    last = [line for line in output.splitlines() if line.strip()][-2:]
    print(f"  done in {time.monotonic() - started:.1f} s: {' / '.join(last)}", flush=True)


class Api:
    """The few reads of Prefect's REST API this script needs (as the UI makes them)."""

    def __init__(self, url: str):
        self.client = httpx.Client(base_url=url.rstrip("/") + "/", timeout=30)

    def post(self, path: str, body: dict):
        response = self.client.post(path, json=body)
        response.raise_for_status()
        return response.json()

    def newest_flow_run(self) -> dict:
        runs = self.post("flow_runs/filter", {"sort": "START_TIME_DESC", "limit": 50})
        top = [run for run in runs if run.get("parent_task_run_id") is None]
        if not top:
            raise SystemExit("screenshot_flow_run: the server has no flow run")
        return top[0]

    def flow_run(self, flow_run_id: str) -> dict:
        response = self.client.get(f"flow_runs/{flow_run_id}")
        response.raise_for_status()
        return response.json()

    def task_run_count(self, flow_run_id: str) -> int:
        return self.post("task_runs/count", {"flow_runs": {"id": {"any_": [flow_run_id]}}})

    def task_run_names(self, flow_run_id: str) -> list[str]:
        runs = self.post("task_runs/filter", {"flow_runs": {"id": {"any_": [flow_run_id]}}, "limit": 200})
        return [run["name"] for run in runs]

    def first_log(self, flow_run_id: str) -> str | None:
        logs = self.post(
            "logs/filter", {"logs": {"flow_run_id": {"any_": [flow_run_id]}}, "sort": "TIMESTAMP_ASC", "limit": 1}
        )
        return logs[0]["message"] if logs else None

    def artifact_keys(self, flow_run_id: str) -> list[str]:
        artifacts = self.post("artifacts/filter", {"artifacts": {"flow_run_id": {"any_": [flow_run_id]}}})
        return sorted({artifact["key"] for artifact in artifacts if artifact.get("key")})


def settled(api: Api, flow_run_id: str) -> tuple[dict, int]:
    """The flow run once it is final and the server has recorded all of its task runs (their
    count is the same over 2 s: the server records them from events, after the flow has ended)."""
    wait_for(
        lambda: api.flow_run(flow_run_id)["state_type"] in ("COMPLETED", "FAILED", "CRASHED", "CANCELLED"),
        60,
        "the flow run's final state",
    )
    counts = [-1]

    def steady() -> bool:
        counts.append(api.task_run_count(flow_run_id))
        return len(counts) >= 5 and counts[-1] == counts[-5] > 0

    wait_for(steady, 60, "the flow run's task runs")
    return api.flow_run(flow_run_id), counts[-1]


def chromium_run(
    chromium: str, profile: Path, args: list[str], timeout_s: float, window: tuple[int, int] = WINDOW
) -> str:
    """Headless Chromium once at ``window`` (default WINDOW); its stdout."""
    return headless_chromium.run(chromium, profile, args, window, timeout_s)


def missing_from_page(
    chromium: str,
    profile: Path,
    url: str,
    expected: list[str],
    any_of: list[str],
    budget_ms: int,
    window: tuple[int, int] = WINDOW,
) -> list[str]:
    dom = html.unescape(
        chromium_run(
            chromium,
            profile,
            [f"--virtual-time-budget={budget_ms}", "--dump-dom", url],
            timeout_s=budget_ms / 1000 + 90,
            window=window,
        )
    )
    missing = [text for text in expected if text not in dom]
    if any_of and not any(text in dom for text in any_of):
        missing.append(f"one of {len(any_of)} task run names")
    return missing


def screenshot(
    chromium: str,
    profile: Path,
    url: str,
    expected: list[str],
    any_of: list[str],
    budget_ms: int,
    target: Path,
    window: tuple[int, int] = WINDOW,
) -> Path:
    """A PNG of ``url`` at ``window`` (width, height) px once its DOM holds every one of ``expected``
    and one of ``any_of`` (if any); written to ``target``."""
    for budget in (budget_ms, 2 * budget_ms, 4 * budget_ms):
        missing = missing_from_page(chromium, profile, url, expected, any_of, budget, window)
        if missing:
            print(f"  not rendered after {budget} ms of virtual time (missing {missing}); waiting longer", flush=True)
            continue
        raw = profile.parent / "screenshot.png"
        raw.unlink(missing_ok=True)
        chromium_run(
            chromium,
            profile,
            [f"--virtual-time-budget={budget}", f"--screenshot={raw}", url],
            timeout_s=budget / 1000 + 90,
            window=window,
        )
        image = Image.open(raw).convert("RGB")
        colours = image.getcolors(maxcolors=1 << 16)
        if colours is not None and len(colours) < 50:
            print(f"  the screenshot has {len(colours)} colours only (blank or loading?); waiting longer", flush=True)
            continue
        return save_small(image, target)
    raise SystemExit(f"{Path(sys.argv[0]).stem}: {url} did not render (missing {missing}) after {4 * budget_ms} ms")


def save_small(image: Image.Image, target: Path) -> Path:
    """Save as an optimised PNG, scaled down (by 0.85 a time) until it is under MAX_BYTES."""
    target.parent.mkdir(parents=True, exist_ok=True)
    while True:
        buffer = io.BytesIO()
        image.save(buffer, format="PNG", optimize=True)
        if buffer.tell() < MAX_BYTES or image.width < 600:
            break
        image = image.resize((int(image.width * 0.85), int(image.height * 0.85)), Image.LANCZOS)
    target.write_bytes(buffer.getvalue())
    print(f"  wrote {target} ({image.width}x{image.height}, {buffer.tell() / 1000:.0f} KB)", flush=True)
    return target


def on_sigterm(signum, frame) -> None:
    raise SystemExit(128 + signum)  # unwinds through the finally blocks: server and processes stopped


def main(argv=None) -> int:
    args = parse_args(argv)
    try:
        chromium = find_chromium()
    except ChromiumMissing as error:
        raise SystemExit(f"screenshot_flow_run: {error}") from None
    signal.signal(signal.SIGTERM, on_sigterm)
    written = []
    with tempfile.TemporaryDirectory(prefix="noisebo-screenshot-") as tmp:
        folder = Path(tmp)
        started = time.monotonic()
        with local_server(folder / "prefect") as env:
            env.pop("NOISEBO_PREFECT_REPORTS", None)  # the run's logs and artifacts are what is shown
            base = env["PREFECT_API_URL"].removesuffix("/api")
            print(
                f"Prefect server: {base} (PREFECT_HOME {env['PREFECT_HOME']}), up in "
                f"{time.monotonic() - started:.1f} s",
                flush=True,
            )
            run_campaign(env, args.config, args.seed, folder)
            api = Api(env["PREFECT_API_URL"])
            run, n_tasks = settled(api, api.newest_flow_run()["id"])
            first_log = api.first_log(run["id"])
            print(f"flow run: {run['name']} ({run['id']}), {run['state_name']}, {n_tasks} task runs", flush=True)
            page = f"{base}/v2/runs/flow-run/{run['id']}"
            expected = [run["name"], f"{n_tasks} Task run"] + ([first_log[:60]] if first_log else [])
            profile = folder / "chromium-profile"
            shots = [(f"{page}?tab=Logs", expected, [], "prefect-flow-run.png")]
            if not args.only_logs:
                shots.append(
                    (f"{page}?tab=TaskRuns", [run["name"]], api.task_run_names(run["id"]), "prefect-flow-run-tasks.png")
                )
                keys = api.artifact_keys(run["id"])
                shots.append((f"{page}?tab=Artifacts", [run["name"], *keys], [], "prefect-flow-run-artifacts.png"))
            for url, texts, any_of, name in shots:
                print(f"screenshot of {url}", flush=True)
                written.append(screenshot(chromium, profile, url, texts, any_of, args.budget_ms, args.out / name))
        print("server stopped", flush=True)
    for path in written:
        print(path.relative_to(ROOT) if path.is_relative_to(ROOT) else path)
    return 0


if __name__ == "__main__":
    sys.exit(main())
