"""`noisebo client`: the instrument-PC client of the network bridge, and a complete instrument-PC
script on it, for a lab working from the installed package alone.

    noisebo client                 # the client (one file, Python 3.8+, standard library) on stdout
    noisebo client --out DIR       # DIR/client.py and DIR/serve_simulator.py
"""

from __future__ import annotations

import sys
from importlib import resources
from pathlib import Path

CLIENT = "client.py"
EXAMPLE = "serve_simulator.py"


def _source(module: str) -> str:
    return (resources.files("noisebo.bridge") / f"{module}.py").read_text(encoding="utf-8")


def run(args) -> int:
    if args.out is None:
        sys.stdout.write(_source("client"))
        return 0
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    written = {out / CLIENT: _source("client"), out / EXAMPLE: _source("serve_simulator")}
    existing = [str(path) for path in written if path.exists()]
    if existing and not args.force:
        from noisebo.cli.common import UsageError

        raise UsageError(f"{', '.join(existing)} already there; --force writes over it")
    for path, text in written.items():
        path.write_text(text, encoding="utf-8")
    print(
        f"wrote {out / CLIENT} (copy it to the instrument PC: `from client import serve_instrument`) "
        f"and {out / EXAMPLE} (a complete instrument-PC script on noisebo's simulators: "
        f"NOISEBO_BRIDGE_TOKEN=TOKEN python {out / EXAMPLE} URL [CONFIG])"
    )
    return 0


def add_parser(commands) -> None:
    client = commands.add_parser(
        "client", help="print or write the instrument-PC client of the network bridge (and an example script)"
    )
    client.add_argument("--out", help="a folder to write client.py and serve_simulator.py into")
    client.add_argument("--force", action="store_true", help="write over files already there")
    client.set_defaults(handler=run)
