"""Screenshot of a campaign's Rerun recording in Rerun's web viewer, for the documentation (docs/watching.md).

    python benchmarks/screenshot_rerun.py [--config PATH] [--seed N] [--recording FILE.rrd] [--out PATH]

Needs headless Chromium (Debian: ``apt-get install -y chromium``; its WebGL runs on the CPU through
SwiftShader, no GPU needed) and the ``rerun`` command of the rerun-sdk installed with noisebo (it
serves the web viewer). It runs one campaign (``noisebo run CONFIG --seed N``: FILE.h5 and its
recording FILE.rrd in a temporary folder, with Prefect's temporary server in the same folder and
its reports off), or takes an existing recording with ``--recording`` (its FILE.h5 beside it). It
serves the recording with ``rerun --serve-web`` on loopback (the web viewer and the gRPC server on
free ports; Rerun's settings and analytics in the temporary folder, analytics off) together with a
blueprint file: the campaign's own layout (``noisebo.view.blueprint``) with the time panel on the
``step`` timeline, following the newest data, so that the viewer ends on the final models. It
opens the viewer in headless Chromium (every host name but 127.0.0.1 unresolvable, so nothing
leaves the machine), drives it through the DevTools protocol and takes a PNG at 1600x1000.

Before the screenshot it waits until the viewer's own state (``viewer_state()`` of the page's
viewer handle: Rerun's Viewer Control API, a protobuf message read here with the field numbers of
rerun-sdk 0.41) says that the recording is open, its ``step`` timeline reaches the campaign's last
frame (from FILE.h5) and the time cursor is on it, and every view of the layout is shown, visible
and reports no error; then until two screenshots 3 s apart are the same (the viewer has drawn
it). It refuses an image of (nearly) one colour, one without the viridis acquisition map, and a
viewer that has crashed. Images over 400 KB are scaled down. The campaign, the Rerun server and
Chromium are stopped at the end, however the script ends (SIGTERM included).
"""

from __future__ import annotations

import noisebo.cli  # noqa: F401 - first: one OpenBLAS thread for this process, before numpy loads (as the command line)
import argparse
import base64
import io
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from urllib.parse import quote

import httpx
import numpy as np
from headless_chromium import ChromiumMissing, find_chromium, stop_group
from PIL import Image
from screenshot_flow_run import ROOT, WINDOW, on_sigterm, run_campaign, save_small

from noisebo.flows.processes import BIN, free_port, start, wait_for

APP_ID = "noisebo"  # the application id of every campaign recording (noisebo.view.rerun_view)
HEADER_PX = 44  # the viewer's top bar: it shows the data's latency while data arrives

READS_VERSION = "0.41."
# Rerun 0.41's GetStateResponse (Viewer Control API), the fields read here: recordings (store id,
# timelines with their range, the time cursor) and the views of the blueprint shown.
STATE_ACTIVE, STATE_RECORDING, STATE_VIEW, STATE_VERSION = 2, 3, 5, 6
RECORDING_STORE, RECORDING_TIMELINE, RECORDING_CURSOR = 1, 2, 3
VIEW_NAME, VIEW_VISIBLE, VIEW_REPORT = 3, 5, 6


def parse_args(argv=None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--config", default="data/configs/forrester.yaml", help="campaign YAML (default: %(default)s)")
    parser.add_argument("--seed", type=int, default=3)
    parser.add_argument(
        "--recording", type=Path, default=None, help="an existing FILE.rrd (FILE.h5 beside it) instead of a campaign"
    )
    parser.add_argument("--out", type=Path, default=ROOT / "docs" / "images" / "rerun-views.png")
    parser.add_argument(
        "--timeout-s",
        type=float,
        default=300,
        help="how long the viewer may take to load and draw the recording (default: %(default)s)",
    )
    return parser.parse_args(argv)


# --- the campaign and what its recording must show ------------------------------------------------


class Expected:
    """What the viewer must show of a campaign: its recording id, last frame on the ``step``
    timeline and view names; and the blueprint that lays them out."""

    def __init__(self, h5: Path):
        import rerun.blueprint as rrb

        from noisebo.config import parse_config
        from noisebo.storage.record import read_record
        from noisebo.view.blueprint import blueprint
        from noisebo.view.frames import n_frames

        record = read_record(h5)
        config = parse_config(record.config, load_plugins=False)
        self.recording_id = h5.stem
        self.last_step = n_frames(record, config) - 1
        self.blueprint = blueprint(config)
        self.blueprint.time_panel = rrb.TimePanel(timeline="step", play_state="following", state="collapsed")

        def views(node) -> list[str]:
            if isinstance(node, rrb.Container):
                return [name for part in node.contents for name in views(part)]
            return [str(node.name)]

        self.views = views(self.blueprint.root_container)

    def save_blueprint(self, path: Path) -> Path:
        self.blueprint.save(APP_ID, str(path))
        return path


def campaign_files(args: argparse.Namespace, folder: Path) -> tuple[Path, Path]:
    """(FILE.rrd, FILE.h5): the given recording, or those of a campaign run now."""
    if args.recording is not None:
        rrd = args.recording.resolve()
    else:
        env = dict(os.environ, PREFECT_HOME=str(folder / "prefect"), NOISEBO_PREFECT_REPORTS="0")
        env.pop("PREFECT_API_URL", None)  # Prefect's temporary server, in the temporary folder
        run_campaign(env, args.config, args.seed, folder, rrd=True)
        found = sorted((folder / "runs").glob("*.rrd"))
        if len(found) != 1:
            raise SystemExit(f"screenshot_rerun: expected one recording in {folder / 'runs'}, found {found}")
        rrd = found[0]
    h5 = rrd.with_suffix(".h5")
    for path in (rrd, h5):
        if not path.is_file():
            raise SystemExit(f"screenshot_rerun: {path} is missing")
    return rrd, h5


# --- the Rerun web viewer -------------------------------------------------------------------------


def serve_recording(rrd: Path, rbl: Path, folder: Path) -> tuple[subprocess.Popen, str]:
    """``rerun --serve-web`` of the recording and blueprint on loopback; (its process, the page's URL)."""
    rerun = str(BIN / "rerun")
    env = dict(
        os.environ,
        XDG_CONFIG_HOME=str(folder / "rerun" / "config"),
        XDG_DATA_HOME=str(folder / "rerun" / "data"),
        XDG_CACHE_HOME=str(folder / "rerun" / "cache"),
    )
    subprocess.run([rerun, "analytics", "disable"], env=env, capture_output=True, timeout=60, check=True)
    web, grpc = free_port(), free_port()
    log = folder / "rerun.log"
    command = [rerun, "--serve-web", "--bind", "127.0.0.1", "--web-viewer-port", str(web), "--port", str(grpc)]
    process = start([*command, str(rrd), str(rbl)], env, log)

    def up() -> bool:
        if process.poll() is not None:
            raise SystemExit(
                f"screenshot_rerun: rerun exited with code {process.returncode}:\n{log.read_text()[-3000:]}"
            )
        try:
            return httpx.get(f"http://127.0.0.1:{web}/", timeout=1).status_code == 200
        except httpx.HTTPError:
            return False

    try:
        wait_for(up, 60, "Rerun's web viewer", [log])
    except BaseException:
        stop_group(process)
        raise
    proxy = quote(f"rerun+http://127.0.0.1:{grpc}/proxy", safe="")
    return process, f"http://127.0.0.1:{web}/?url={proxy}&hide_welcome_screen&persist=0"


# --- headless Chromium through the DevTools protocol -----------------------------------------------


class DevTools:
    """One page of a headless Chromium driven through the DevTools protocol; ``close`` stops it."""

    def __init__(self, chromium: str, profile: Path, window: tuple[int, int]):
        from websockets.sync.client import connect

        profile.mkdir(parents=True, exist_ok=True)
        command = [
            chromium,
            "--headless=new",
            "--no-sandbox",
            "--hide-scrollbars",
            "--no-first-run",
            "--disable-extensions",
            "--mute-audio",
            "--enable-unsafe-swiftshader",  # WebGL on the CPU (SwiftShader): the viewer draws with it
            "--host-resolver-rules=MAP * ~NOTFOUND, EXCLUDE 127.0.0.1",  # nothing but loopback
            "--remote-debugging-port=0",  # a free port, written to DevToolsActivePort
            f"--user-data-dir={profile}",
            f"--window-size={window[0]},{window[1]}",
            "about:blank",
        ]
        self.process = subprocess.Popen(
            command, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True
        )
        self.messages = 0
        try:
            active = profile / "DevToolsActivePort"
            wait_for(lambda: active.is_file() and len(active.read_text().split()) >= 2, 60, "Chromium's DevTools port")
            port = int(active.read_text().split()[0])
            pages = [
                t for t in httpx.get(f"http://127.0.0.1:{port}/json/list", timeout=10).json() if t["type"] == "page"
            ]
            self.socket = connect(pages[0]["webSocketDebuggerUrl"], max_size=None, open_timeout=30)
            self.call(
                "Emulation.setDeviceMetricsOverride",
                width=window[0],
                height=window[1],
                deviceScaleFactor=1,
                mobile=False,
            )
        except BaseException:
            stop_group(self.process)
            raise

    def call(self, method: str, **params) -> dict:
        self.messages += 1
        self.socket.send(json.dumps({"id": self.messages, "method": method, "params": params}))
        while True:
            message = json.loads(self.socket.recv(timeout=120))
            if message.get("id") == self.messages:  # anything else is an event, not asked for
                if "error" in message:
                    raise RuntimeError(f"DevTools {method}: {message['error']}")
                return message["result"]

    def evaluate(self, expression: str):
        result = self.call("Runtime.evaluate", expression=expression, returnByValue=True)
        if "exceptionDetails" in result:
            raise RuntimeError(f"{expression}: {result['exceptionDetails'].get('text')}")
        return result["result"].get("value")

    def screenshot(self) -> Image.Image:
        data = self.call("Page.captureScreenshot", format="png")["data"]
        return Image.open(io.BytesIO(base64.b64decode(data))).convert("RGB")

    def close(self) -> None:
        try:
            self.socket.close()
        finally:
            stop_group(self.process)


# --- the viewer's state ----------------------------------------------------------------------------


def _varint(data: bytes, i: int) -> tuple[int, int]:
    value = shift = 0
    while True:
        byte = data[i]
        i += 1
        value |= (byte & 0x7F) << shift
        shift += 7
        if byte < 0x80:
            return value, i


def fields(data: bytes) -> list[tuple[int, int | bytes]]:
    """The (field number, value) pairs of one protobuf message: ints, or bytes for strings and
    nested messages."""
    out: list[tuple[int, int | bytes]] = []
    i = 0
    while i < len(data):
        key, i = _varint(data, i)
        number, wire = key >> 3, key & 7
        value: int | bytes
        if wire == 0:
            value, i = _varint(data, i)
        elif wire in (1, 5):
            size = 8 if wire == 1 else 4
            value, i = int.from_bytes(data[i : i + size], "little"), i + size
        elif wire == 2:
            size, i = _varint(data, i)
            value, i = data[i : i + size], i + size
        else:
            raise ValueError(f"unsupported protobuf wire type {wire}")
        out.append((number, value))
    return out


def field(data: bytes, number: int, default=None):
    """The (last) value of field ``number`` of a message (the default where absent: a zero)."""
    found = [value for n, value in fields(data) if n == number]
    return found[-1] if found else default


def timeline_name(data: bytes) -> str:
    return field(field(data, 1, b""), 1, b"").decode()


def viewer_problems(state: bytes, expected: Expected) -> list[str]:
    """What the viewer's state says is not shown yet (empty when all of it is)."""
    store = f"Recording:{APP_ID}:{expected.recording_id}"
    problems = []
    if field(state, STATE_ACTIVE, b"").decode() != store:
        return [f"the recording {expected.recording_id} is not open"]
    for recording in (value for n, value in fields(state) if n == STATE_RECORDING):
        if field(recording, RECORDING_STORE, b"").decode() != store:
            continue
        ends = {
            timeline_name(timeline): field(field(timeline, 3, b""), 2, 0)
            for n, timeline in fields(recording)
            if n == RECORDING_TIMELINE
        }
        cursor = field(recording, RECORDING_CURSOR, b"")
        at = (timeline_name(cursor), field(field(cursor, 3, b""), 1, 0))
        if ends.get("step") != expected.last_step:
            problems.append(f"the step timeline reaches {ends.get('step')} of {expected.last_step}")
        if at != ("step", expected.last_step):
            problems.append(f"the time cursor is at {at[0]} {at[1]}, not step {expected.last_step}")
    views = {}
    for view in (value for n, value in fields(state) if n == STATE_VIEW):
        reports = [value for n, value in fields(view) if n == VIEW_REPORT]
        views[field(view, VIEW_NAME, b"").decode()] = (field(view, VIEW_VISIBLE, 0), reports)
    for name in expected.views:
        if name not in views:
            problems.append(f"no view {name!r}")
        elif not views[name][0]:
            problems.append(f"the view {name!r} is hidden")
        elif views[name][1]:
            problems.append(f"the view {name!r} reports {views[name][1]}")
    return problems


def viewer_state(page: DevTools) -> bytes | None:
    """The viewer's encoded state; None before the viewer has started. Exits if it has crashed."""
    if not page.evaluate("typeof window._handle !== 'undefined'"):
        return None
    if page.evaluate("window._handle.has_panicked()"):
        raise SystemExit(f"screenshot_rerun: the viewer crashed: {page.evaluate('window._handle.panic_message()')}")
    encoded = page.evaluate("btoa(Array.from(window._handle.viewer_state(), (b) => String.fromCharCode(b)).join(''))")
    return base64.b64decode(encoded)


# --- the picture -----------------------------------------------------------------------------------


def picture_problems(image: Image.Image) -> list[str]:
    """Why ``image`` is not a drawn viewer: (nearly) one colour, or no acquisition map (viridis)."""
    import matplotlib

    colours = image.getcolors(maxcolors=1 << 16)
    if colours is not None and len(colours) < 50:
        return [f"the screenshot has {len(colours)} colours only"]
    viridis = np.asarray(matplotlib.colormaps["viridis"](np.linspace(0, 1, 32)))[:, :3] * 255
    pixels = np.asarray(image, dtype=float).reshape(-1, 3)[::7]
    nearest = np.min(((pixels[:, None, :] - viridis[None]) ** 2).sum(-1), axis=1)
    share = float(np.mean(nearest < 15**2))
    return [] if share >= 0.02 else [f"no acquisition map: {share:.1%} of the pixels are viridis colours"]


def settled_screenshot(page: DevTools, expected: Expected, deadline: float) -> Image.Image:
    """A screenshot once the viewer's state shows all of the recording and two screenshots 3 s
    apart are the same below the top bar."""
    last_problems: list[str] = []
    while True:
        state = viewer_state(page)
        problems = ["the viewer has not started"] if state is None else viewer_problems(state, expected)
        if not problems:
            break
        if problems != last_problems:
            print("  waiting:", "; ".join(problems), flush=True)
            last_problems = problems
        if time.monotonic() > deadline:
            version = field(state, STATE_VERSION, b"").decode() if state is not None else "not started"
            hint = (
                ""
                if version.startswith(READS_VERSION)
                else f" (read as rerun {READS_VERSION}'s; the viewer: {version})"
            )
            raise SystemExit(f"screenshot_rerun: the viewer did not show the recording in time: {problems}{hint}")
        time.sleep(2)
    version = field(state, STATE_VERSION, b"").decode()
    print(f"  the viewer ({version}) shows the recording up to step {expected.last_step}", flush=True)
    previous = page.screenshot()
    while True:
        time.sleep(3)
        image = page.screenshot()
        below = (0, HEADER_PX, *image.size)
        same = np.array_equal(np.asarray(image.crop(below)), np.asarray(previous.crop(below)))
        problems = picture_problems(image)
        if same and not problems:
            state = viewer_state(page)
            problems = viewer_problems(state, expected) if state is not None else ["the viewer has gone"]
            if problems:
                raise SystemExit(f"screenshot_rerun: the viewer changed while shot: {problems}")
            return image
        if time.monotonic() > deadline:
            raise SystemExit(f"screenshot_rerun: the viewer did not settle in time ({problems or 'still drawing'})")
        previous = image


def main(argv=None) -> int:
    args = parse_args(argv)
    try:
        chromium = find_chromium()
    except ChromiumMissing as error:
        raise SystemExit(f"screenshot_rerun: {error}") from None
    signal.signal(signal.SIGTERM, on_sigterm)
    with tempfile.TemporaryDirectory(prefix="noisebo-screenshot-") as tmp:
        folder = Path(tmp)
        rrd, h5 = campaign_files(args, folder)
        expected = Expected(h5)
        rbl = expected.save_blueprint(folder / "view.rbl")
        server, url = serve_recording(rrd, rbl, folder)
        try:
            print(f"Rerun web viewer: {url}", flush=True)
            page = DevTools(chromium, folder / "chromium-profile", WINDOW)
            try:
                page.call("Page.navigate", url=url)
                image = settled_screenshot(page, expected, time.monotonic() + args.timeout_s)
            finally:
                page.close()
        finally:
            stop_group(server)
        print("Rerun server stopped", flush=True)
        written = save_small(image, args.out)
    print(written.relative_to(ROOT) if written.is_relative_to(ROOT) else written)
    return 0


if __name__ == "__main__":
    sys.exit(main())
