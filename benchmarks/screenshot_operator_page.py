"""A screenshot of the bridge's operator's page (``/``) while a campaign runs, for the docs and the README.

    python benchmarks/screenshot_operator_page.py [--out PNG] [--points N] [--seed N]

Needs headless Chromium (Debian: ``apt-get install -y chromium``). It runs the real command,
``noisebo run`` of data/configs/forrester_remote.yaml (the Forrester campaign with its instrument
behind the bridge) on a free loopback port, with a random token and its files in a temporary folder,
and the instrument PC's side, the stdlib client ``noisebo.bridge.client.serve_instrument``, on a
thread of this process measuring the simulated Forrester instrument (each shot drawn as the
campaign's own simulator draws it, as noisebo/bridge/serve_simulator.py does). The client
holds the first shot of point N (``--points``, 8 by default: the 3 seed points and 5 BO steps) until
the page has been shot, so the page shows a campaign under way: N points measured, the models'
pictures, point N being measured. The page's DOM (``--dump-dom``) is checked to show the campaign
before the screenshot is taken at 1280x1000 (``docs/images/operator-page.png`` by default); then the
hold is released and the campaign runs to its end.

tests/e2e/test_operator_page.py drives the same campaign and the same Chromium calls.
"""

from __future__ import annotations

import noisebo.cli  # noqa: F401 - first: one OpenBLAS thread for this process, before numpy loads (as the command line)
import argparse
import html
import json
import os
import re
import secrets
import signal
import subprocess
import sys
import tempfile
import threading
import time
import urllib.error
import urllib.request
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import headless_chromium
import numpy as np
import yaml
from headless_chromium import ChromiumMissing, find_chromium

ROOT = Path(__file__).resolve().parents[1]
CONFIG = ROOT / "data" / "configs" / "forrester_remote.yaml"
SIMULATED = ROOT / "data" / "configs" / "forrester.yaml"  # the instrument the client simulates
WINDOW = (1280, 1000)
START_TIMEOUT_S = 300  # Prefect's temporary server, JAX's first compilations, the seed points
SILENCE_S = 600  # the held shot must not time out while the page is shot


def chromium_run(chromium: str, profile: Path, args: list[str], timeout_s: float = 120) -> str:
    """Headless Chromium once at WINDOW; its stdout."""
    return headless_chromium.run(chromium, profile, args, WINDOW, timeout_s)


def page_text(dom: str) -> str:
    """What a person reads of a page: its text without tags, entities decoded, spaces collapsed."""
    return " ".join(html.unescape(re.sub(r"<[^>]+>", " ", dom)).split())


@dataclass
class Running:
    """A campaign under way whose instrument PC holds the first shot of point ``held_at``."""

    url: str  # the bridge, http://127.0.0.1:PORT
    token: str
    path: Path  # the campaign's HDF5 file (being written)
    held_at: int
    process: subprocess.Popen
    log: Path
    release: threading.Event
    client: threading.Thread
    client_result: dict = field(default_factory=dict)

    @property
    def page_url(self) -> str:
        return f"{self.url}/?token={self.token}"

    def status(self) -> dict:
        request = urllib.request.Request(self.url + "/status", headers={"Authorization": f"Bearer {self.token}"})
        with urllib.request.urlopen(request, timeout=30) as answer:
            return json.loads(answer.read())

    def finish(self, timeout_s: float = 300) -> tuple[int, str]:
        """Release the held shot and wait for the campaign's end: (exit code of `noisebo run`,
        the client's final status)."""
        self.release.set()
        code = self.process.wait(timeout=timeout_s)
        self.client.join(60)
        return code, self.client_result.get("status", "")


def write_config(folder: Path, port: int) -> Path:
    data = yaml.safe_load(CONFIG.read_text())
    data["instrument"]["settings"].update(port=port, silence_s=SILENCE_S)
    path = folder / "forrester_remote.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def simulated_measure(held_at: int, holding: threading.Event, release: threading.Event):
    """The instrument PC's ``measure``: the simulated Forrester instrument; the first shot of point
    ``held_at`` waits for ``release`` (``holding`` set while it waits)."""
    from noisebo.config import load_config
    from noisebo.instruments import build
    from noisebo.instruments.registry import validated
    from noisebo.keys import MEASURE, numpy_rng

    instrument = build(validated(load_config(SIMULATED)).instrument)

    def measure(request):
        if request.point == held_at and request.shot == 0:
            holding.set()
            release.wait()
        rng = numpy_rng(request.seed, MEASURE, request.point, request.shot)
        return instrument.simulate(np.asarray(request.x), request.t, rng).value

    return measure


@contextmanager
def running_campaign(folder: Path, held_at: int = 8, seed: int = 0, env: dict | None = None):
    """``noisebo run`` of the remote Forrester campaign in ``folder`` with the instrument PC's
    client on a thread, yielded as ``Running`` once ``held_at`` points are measured and the first
    shot of the next is held; on leaving, the hold is released and whatever is still running is
    stopped."""
    from noisebo.bridge.client import serve_instrument
    from noisebo.flows.processes import BIN, free_port, start, stop

    folder.mkdir(parents=True, exist_ok=True)
    port, token = free_port(), secrets.token_urlsafe(32)
    config = write_config(folder, port)
    out, log = folder / "runs", folder / "noisebo-run.log"
    run_env = {**(os.environ if env is None else env), "NOISEBO_BRIDGE_TOKEN": token}
    process = start(
        [str(BIN / "noisebo"), "run", str(config), "--seed", str(seed), "--out", str(out), "--no-rrd"], run_env, log
    )
    holding, release = threading.Event(), threading.Event()
    url, result = f"http://127.0.0.1:{port}", {}
    said: list[str] = []

    def client():
        try:
            result["status"] = serve_instrument(
                url, token, simulated_measure(held_at, holding, release), poll_s=5.0, retry_s=0.5, log=said.append
            )
        except Exception as error:  # noqa: BLE001 - said by whoever waits on the campaign
            result["error"] = f"{type(error).__name__}: {error}"

    thread = threading.Thread(target=client, name="instrument-pc", daemon=True)
    thread.start()
    running = Running(
        url, token, out / f"forrester_remote_reward_s{seed:04d}.h5", held_at, process, log, release, thread, result
    )
    try:
        deadline = time.monotonic() + START_TIMEOUT_S
        while not holding.wait(0.5):
            if process.poll() is not None or "error" in result or time.monotonic() > deadline:
                raise RuntimeError(
                    f"the campaign never came to point {held_at} (noisebo run "
                    f"{'exited ' + str(process.returncode) if process.poll() is not None else 'running'}"
                    f"; client: {result or said[-3:]})\n{log.read_text()[-3000:]}"
                )
        while (running.status().get("current") or {}).get("point") != held_at:  # the campaign's view of the same
            time.sleep(0.1)
        yield running
    finally:
        release.set()
        try:
            process.wait(timeout=120)
        except subprocess.TimeoutExpired:
            stop(process)
        thread.join(30)


def screenshot(chromium: str, profile: Path, url: str, target: Path) -> Path:
    """A PNG of ``url`` at WINDOW, written to ``target``."""
    target.parent.mkdir(parents=True, exist_ok=True)
    target.unlink(missing_ok=True)
    chromium_run(chromium, profile, [f"--screenshot={target}", url])
    if not target.exists():
        raise RuntimeError(f"chromium wrote no screenshot of {url}")
    return target


def rendered(text: str, running: Running, status: dict) -> list[str]:
    """What a rendered page of ``running`` must say, missing from ``text`` (the page's text)."""
    current = status["current"]
    expected = [
        f"noisebo campaign {status['campaign']}",
        f"measuring point {running.held_at} (BO step {current['step']})",
        f"shot 1 of {current['shots_wanted']}",
        f"{running.held_at} of {status['points_total']} points finished, {status['shots']} shots",  # none under way yet
        "instrument PC: connected",
        "What the campaign has learned",
        "f: the model (mean ± 2 sd) and the measured points",
        "single-shot noise: the model and the measured sd",
        "Last points",
    ]
    return [line for line in expected if line not in text]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=ROOT / "docs" / "images" / "operator-page.png")
    parser.add_argument("--points", type=int, default=8, help="points measured when the page is shot (default 8)")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    try:
        chromium = find_chromium()
    except ChromiumMissing as error:
        print(f"screenshot_operator_page: {error}", file=sys.stderr)
        return 2
    signal.signal(signal.SIGTERM, lambda signum, frame: sys.exit(128 + signum))  # unwinds: processes stopped
    with tempfile.TemporaryDirectory(prefix="noisebo-operator-page-") as tmp:
        folder = Path(tmp)
        with running_campaign(folder, args.points, args.seed) as running:
            status = running.status()
            text = page_text(chromium_run(chromium, folder / "chromium", ["--dump-dom", running.page_url]))
            missing = rendered(text, running, status)
            if missing:
                print(f"screenshot_operator_page: the page does not show {missing}:\n{text[:2000]}", file=sys.stderr)
                return 1
            screenshot(chromium, folder / "chromium", running.page_url, args.out)
            print(
                f"wrote {args.out} ({args.out.stat().st_size / 1000:.0f} KB): {status['campaign']} at point "
                f"{running.held_at} of {status['points_total']}",
                flush=True,
            )
            code, final = running.finish()
        print(f"the campaign then ran to its end: noisebo run exited {code}, the instrument PC saw {final!r}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
