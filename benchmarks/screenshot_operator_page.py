"""Screenshots of the bridge's operator's page (``/``) in each phase of a campaign, for the docs and the README.

    python benchmarks/screenshot_operator_page.py [--out-dir DIR] [--points N] [--seed N]

Needs headless Chromium (Debian: ``apt-get install -y chromium``). It runs the real command,
``noisebo run`` of data/configs/forrester_remote.yaml (the Forrester campaign with its instrument
behind the bridge) on a free loopback port, with a random token and its files in a temporary folder,
and the instrument PC's side, the stdlib client ``noisebo.bridge.client.serve_instrument``, on a
thread of this process measuring the simulated Forrester instrument (each shot drawn as the
campaign's own simulator draws it, as noisebo/bridge/serve_simulator.py does). The page is shot
(1280x1000) in each phase, after its DOM (``--dump-dom``) is checked to show that phase truly:

- ``operator-page-waiting.png``: the campaign waits for the instrument PC, which has not connected
  yet (the client starts once the page is shot);
- ``operator-page-deciding.png``: the campaign decides a BO step. A decision takes 0.05-0.5 s here,
  less than Chromium takes to start, so the page is caught as the bridge serves it (``/status``
  polled until it says "deciding", the page fetched at once) and Chromium renders that HTML;
- ``operator-page.png``: the client holds the first shot of point N (``--points``, 8 by default:
  the 3 seed points and 5 BO steps), so the page shows N points measured, the models' pictures,
  point N being measured;
- ``operator-page-ended.png``: the hold released, the campaign completes; the bridge stops within
  a second of the end, so the page it serves then is caught as the deciding one is.

The PNGs go to docs/images by default. tests/e2e/test_operator_page.py drives the same campaign
and the same Chromium calls.
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
import urllib.request
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import headless_chromium
import numpy as np
import yaml
from headless_chromium import ChromiumMissing, find_chromium

from noisebo.bridge.page import number

ROOT = Path(__file__).resolve().parents[1]
CONFIG = ROOT / "data" / "configs" / "forrester_remote.yaml"
SIMULATED = ROOT / "data" / "configs" / "forrester.yaml"  # the instrument the client simulates
SCHEDULE = yaml.safe_load(CONFIG.read_text())["schedule"]
WINDOW = (1280, 1000)
START_TIMEOUT_S = 300  # Prefect's temporary server, JAX's first compilations, the seed points
SILENCE_S = 600  # the held shot must not time out while the page is shot
POLL_S = 0.02  # how often /status is asked while a phase that lasts a fraction of a second is awaited
PNG = {  # the screenshot of each phase, in --out-dir
    "waiting": "operator-page-waiting.png",
    "deciding": "operator-page-deciding.png",
    "measuring": "operator-page.png",
    "ended": "operator-page-ended.png",
}
MAX_PNG_BYTES = 400_000  # a larger screenshot is reduced to 256 colours


def chromium_run(chromium: str, profile: Path, args: list[str], timeout_s: float = 120) -> str:
    """Headless Chromium once at WINDOW; its stdout."""
    return headless_chromium.run(chromium, profile, args, WINDOW, timeout_s)


def page_text(dom: str) -> str:
    """What a person reads of a page: its text without style or tags, entities decoded, spaces collapsed."""
    dom = re.sub(r"<style[^>]*>.*?</style>", " ", dom, flags=re.DOTALL)
    return " ".join(html.unescape(re.sub(r"<[^>]+>", " ", dom)).split())


@dataclass
class Served:
    """The operator's page as the bridge served it (``html``), and ``/status`` asked just before."""

    status: dict
    html: str

    def saved(self, path: Path) -> str:
        """The page written to ``path``: its file:// URL, for Chromium."""
        path.write_text(self.html)
        return path.resolve().as_uri()


@dataclass
class Running:
    """A campaign under way whose instrument PC connects on ``connect()`` and then holds the first
    shot of point ``held_at`` until ``finish()``."""

    url: str  # the bridge, http://127.0.0.1:PORT
    token: str
    path: Path  # the campaign's HDF5 file (being written)
    held_at: int
    process: subprocess.Popen
    log: Path
    connected: threading.Event
    holding: threading.Event
    release: threading.Event
    client: threading.Thread
    client_result: dict = field(default_factory=dict)
    said: list = field(default_factory=list)  # the client's log lines
    ended: Served | None = None  # the page served once the campaign had ended (set by finish)

    @property
    def page_url(self) -> str:
        return f"{self.url}/?token={self.token}"

    def status(self) -> dict:
        request = urllib.request.Request(self.url + "/status", headers={"Authorization": f"Bearer {self.token}"})
        with urllib.request.urlopen(request, timeout=30) as answer:
            return json.loads(answer.read())

    def page(self) -> str:
        """The operator's page as the bridge serves it now (its HTML)."""
        with urllib.request.urlopen(self.page_url, timeout=30) as answer:
            return answer.read().decode()

    def connect(self) -> None:
        """Start the instrument PC's client."""
        self.connected.set()

    def _trouble(self, what: str) -> RuntimeError:
        code = self.process.poll()
        return RuntimeError(
            f"{what} (noisebo run {'running' if code is None else f'exited {code}'}; "
            f"client: {self.client_result or self.said[-3:]})\n{self.log.read_text()[-3000:]}"
        )

    def catch_deciding(self, timeout_s: float = START_TIMEOUT_S) -> Served:
        """The page served while the campaign decides a BO step. A decision lasts a fraction of a
        second, so ``/status`` is asked every POLL_S until it says "deciding", and the page is
        fetched at once; it is kept when it shows that decision with the same finished points (the
        decision may have ended in between: the next one is tried). RuntimeError when none is
        caught before the instrument PC holds its shot at point ``held_at``."""
        deadline = time.monotonic() + timeout_s
        while True:
            status = self.status()
            if status["now"] == "deciding":
                served = self.page()
                text = page_text(served)
                if "deciding BO step" in text and f"{status['points']} of {status['points_total']} points" in text:
                    return Served(status, served)
            if self.holding.is_set() or self.process.poll() is not None or time.monotonic() > deadline:
                raise self._trouble(f"the page was never caught deciding before point {self.held_at}")
            time.sleep(POLL_S)

    def wait_held(self, timeout_s: float = START_TIMEOUT_S) -> None:
        """Wait until ``held_at`` points are measured and the client holds the first shot of the next."""
        deadline = time.monotonic() + timeout_s
        while not self.holding.wait(0.5):
            if self.process.poll() is not None or "error" in self.client_result or time.monotonic() > deadline:
                raise self._trouble(f"the campaign never came to point {self.held_at}")
        while (self.status().get("current") or {}).get("point") != self.held_at:  # the campaign's view of it
            time.sleep(0.1)

    def finish(self, timeout_s: float = 300) -> tuple[int, str]:
        """Release the held shot and wait for the campaign's end: (exit code of `noisebo run`, the
        client's final status); the page served at the end is kept as ``ended`` (``await_end``)."""
        self.release.set()
        code = self.await_end(timeout_s)
        self.client.join(60)
        return code, self.client_result.get("status", "")

    def terminate(self, timeout_s: float = 120) -> int:
        """SIGTERM to `noisebo run`, as a person's ``kill`` would: its exit code; the page served
        once the campaign has recorded its end is kept as ``ended`` (``await_end``)."""
        self.process.send_signal(signal.SIGTERM)
        return self.await_end(timeout_s)

    def await_end(self, timeout_s: float) -> int:
        """Wait for `noisebo run` to exit: its exit code. The bridge stops within a second of the
        campaign's end, so ``/status`` is asked every POLL_S until it says the campaign has ended,
        and the page served then is kept as ``ended`` (None when the bridge stopped first)."""
        deadline = time.monotonic() + timeout_s
        while self.ended is None and self.process.poll() is None and time.monotonic() < deadline:
            try:
                status = self.status()
                if status["status"] not in ("running", "starting"):
                    self.ended = Served(status, self.page())
            except OSError:  # the bridge has stopped
                break
            time.sleep(POLL_S)
        return self.process.wait(timeout=max(deadline - time.monotonic(), 1.0))


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
    """``noisebo run`` of the remote Forrester campaign in ``folder``, yielded as ``Running`` as
    soon as its bridge serves the campaign, waiting for an instrument PC: the client, on a thread,
    starts on ``Running.connect()`` and holds the first shot of point ``held_at`` until
    ``Running.finish()``. On leaving, the hold is released and whatever is still running is
    stopped (a campaign whose client never connected at once, with SIGTERM)."""
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
    connected, holding, release, leaving = threading.Event(), threading.Event(), threading.Event(), threading.Event()
    url, result, said = f"http://127.0.0.1:{port}", {}, []

    def client():
        connected.wait()
        if leaving.is_set():
            return
        try:
            result["status"] = serve_instrument(
                url, token, simulated_measure(held_at, holding, release), poll_s=5.0, retry_s=0.5, log=said.append
            )
        except Exception as error:  # noqa: BLE001 - said by whoever waits on the campaign
            result["error"] = f"{type(error).__name__}: {error}"

    thread = threading.Thread(target=client, name="instrument-pc", daemon=True)
    thread.start()
    path = out / f"forrester_remote_reward_s{seed:04d}.h5"
    running = Running(url, token, path, held_at, process, log, connected, holding, release, thread, result, said)
    try:
        deadline = time.monotonic() + START_TIMEOUT_S
        while True:
            try:
                if running.status().get("now"):  # the campaign's first state is committed
                    break
            except OSError:  # not listening yet
                pass
            if process.poll() is not None or time.monotonic() > deadline:
                raise running._trouble("the bridge never served the campaign")
            time.sleep(0.2)
        yield running
    finally:
        if not connected.is_set():
            leaving.set()
            connected.set()
            stop(process)
        release.set()
        try:
            process.wait(timeout=120)
        except subprocess.TimeoutExpired:
            stop(process)
        thread.join(30)


def shows(phase: str, text: str, status: dict) -> list[str]:
    """What the page's text must say in ``phase`` ("waiting", "deciding", "measuring", "ended"),
    given ``/status`` asked just before, and is missing from ``text``; and any placeholder or
    Python repr the text holds instead of a value."""
    current = status.get("current") or {}
    where = ""
    if current:
        kind = "seed point" if current["step"] == 0 else f"BO step {current['step']} of {SCHEDULE['n_steps']}"
        where = (
            f"point {current['point']} ({kind}) at x = {number(tuple(current['x']))}, t = {number(current['t'])} s: "
            f"shot {current['shot'] + 1} of {current['shots_wanted']}"
        )
    failed = status["failed_attempts"]
    expected = [
        f"noisebo campaign {status['campaign']}",
        # finished work only: the shots of a point under way would follow as "(and ...)"
        f"{status['points']} of {status['points_total']} points finished, {status['shots']} shots, "
        f"{failed} failed attempt{'s' * (failed != 1)}; instrument time spent",
        "What the campaign has learned",
        "f: the model (mean ± 2 sd) and the measured points",
        "single-shot noise: the model and the measured sd",
        "Last points",
    ]
    expected += {
        "waiting": [
            f"waiting for the instrument PC to connect, to measure {where}",
            "instrument PC: not connected yet",
            "Last points none yet",
        ],
        "deciding": [
            f"deciding BO step {status['points'] - SCHEDULE['n_seed'] + 1} of {SCHEDULE['n_steps']}: "
            "where and how long to measure next",
            "instrument PC: connected, waiting for the next shot",
        ],
        "measuring": [f"measuring {where}", "instrument PC: connected"],
        "ended": [
            f"the campaign has ended: {status['status']}"
            + (f" ({status['reason']})" if status["reason"] else f", all {status['points']} points measured"),
            "This page no longer reloads itself",
        ],
    }[phase]
    missing = [line for line in expected if line not in text]
    found = re.findall(r"\b(?:None|nan|NaN|inf|True|False|Traceback)\b|(?:^|[\s(=])-(?=$|[\s),])", text)
    return missing + [f"a placeholder or repr: {word.strip()!r}" for word in found]


def screenshot(chromium: str, profile: Path, url: str, target: Path) -> Path:
    """A PNG of ``url`` at WINDOW, written to ``target`` (reduced to 256 colours when over MAX_PNG_BYTES)."""
    target.parent.mkdir(parents=True, exist_ok=True)
    target.unlink(missing_ok=True)
    chromium_run(chromium, profile, [f"--screenshot={target}", url])
    if not target.exists():
        raise RuntimeError(f"chromium wrote no screenshot of {url}")
    if target.stat().st_size > MAX_PNG_BYTES:
        from PIL import Image

        with Image.open(target) as image:
            reduced = image.convert("RGB").quantize(256)
        reduced.save(target, optimize=True)
    return target


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out-dir", type=Path, default=ROOT / "docs" / "images", help="where the PNGs go")
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

        def shoot(phase: str, url: str, status: dict) -> None:
            text = page_text(chromium_run(chromium, folder / "chromium", ["--dump-dom", url]))
            missing = shows(phase, text, status)
            if missing:
                raise RuntimeError(f"the page {phase} does not show {missing}:\n{text[:2000]}")
            png = screenshot(chromium, folder / "chromium", url, args.out_dir / PNG[phase])
            print(f"wrote {png} ({png.stat().st_size / 1000:.0f} KB): {phase}, {status['campaign']}", flush=True)

        try:
            with running_campaign(folder, args.points, args.seed) as running:
                shoot("waiting", running.page_url, running.status())
                running.connect()
                deciding = running.catch_deciding()
                shoot("deciding", deciding.saved(folder / "deciding.html"), deciding.status)
                running.wait_held()
                shoot("measuring", running.page_url, running.status())
                code, final = running.finish()
                if running.ended is None:
                    raise RuntimeError("the bridge stopped before its page could be read at the campaign's end")
                shoot("ended", running.ended.saved(folder / "ended.html"), running.ended.status)
        except RuntimeError as error:
            print(f"screenshot_operator_page: {error}", file=sys.stderr)
            return 1
        print(f"the campaign ran to its end: noisebo run exited {code}, the instrument PC saw {final!r}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
