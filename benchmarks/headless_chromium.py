"""Headless Chromium for the screenshot scripts and the operator's page check: find it, run it
once, stop its process group."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
from pathlib import Path

CHROMIUMS = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable")
INSTALL_CHROMIUM = (
    "headless Chromium is needed and was not found on PATH "
    f"(tried {', '.join(CHROMIUMS)}); on Debian or Ubuntu: sudo apt-get update && "
    "sudo apt-get install -y chromium"
)


class ChromiumMissing(RuntimeError):
    pass


def find_chromium() -> str:
    """The path of a Chromium (or Chrome) binary; ``ChromiumMissing`` saying how to install one."""
    for name in CHROMIUMS:
        found = shutil.which(name)
        if found:
            return found
    raise ChromiumMissing(INSTALL_CHROMIUM)


def run(chromium: str, profile: Path, args: list[str], window: tuple[int, int], timeout_s: float = 120) -> str:
    """Headless Chromium once at ``window`` (width, height) px (its own profile and process group,
    stopped on any exit); its stdout."""
    command = [
        chromium,
        "--headless=new",
        "--no-sandbox",
        "--disable-gpu",
        "--hide-scrollbars",
        "--no-first-run",
        "--disable-extensions",
        "--mute-audio",
        f"--user-data-dir={profile}",
        f"--window-size={window[0]},{window[1]}",
        *args,
    ]
    process = subprocess.Popen(
        command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True
    )
    try:
        output, errors = process.communicate(timeout=timeout_s)
    finally:
        stop_group(process)
    if process.returncode != 0:
        raise RuntimeError(f"chromium exited with code {process.returncode}: {' '.join(command)}\n{errors[-2000:]}")
    return output


def stop_group(process: subprocess.Popen, grace_s: float = 10) -> None:
    """SIGTERM to the process group, SIGKILL after ``grace_s`` (nothing if it has ended)."""
    if process.poll() is None:
        try:
            os.killpg(process.pid, signal.SIGTERM)
            process.wait(timeout=grace_s)
        except ProcessLookupError:
            pass
        except subprocess.TimeoutExpired:
            os.killpg(process.pid, signal.SIGKILL)
            process.wait()
