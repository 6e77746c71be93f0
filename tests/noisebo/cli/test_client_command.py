"""`noisebo client`: the bridge's instrument-PC client and the example script, from the installed
package (noisebo/cli/client.py)."""

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[3]


def noisebo(*args, cwd):
    return subprocess.run(
        [sys.executable, "-m", "noisebo.cli", *args], cwd=cwd, capture_output=True, text=True, timeout=120, check=False
    )


def test_client_prints_the_client_file(tmp_path):
    out = noisebo("client", cwd=tmp_path)
    assert out.returncode == 0 and out.stdout == (ROOT / "noisebo" / "bridge" / "client.py").read_text()


def test_client_out_writes_the_client_and_the_example_and_keeps_what_is_there(tmp_path):
    out = noisebo("client", "--out", "pc", cwd=tmp_path)
    assert out.returncode == 0 and "pc/client.py" in out.stdout and "pc/serve_simulator.py" in out.stdout
    assert (tmp_path / "pc" / "client.py").read_text() == (ROOT / "noisebo" / "bridge" / "client.py").read_text()
    example = (tmp_path / "pc" / "serve_simulator.py").read_text()
    assert example == (ROOT / "noisebo" / "bridge" / "serve_simulator.py").read_text()
    (tmp_path / "pc" / "client.py").write_text("mine")
    again = noisebo("client", "--out", "pc", cwd=tmp_path)
    assert again.returncode == 2 and "already there; --force writes over it" in again.stderr
    assert (tmp_path / "pc" / "client.py").read_text() == "mine"
    assert noisebo("client", "--out", "pc", "--force", cwd=tmp_path).returncode == 0
    assert (tmp_path / "pc" / "client.py").read_text() != "mine"
