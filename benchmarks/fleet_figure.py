"""The fleet benchmark's figure: error against wall time for each setting, and the wall time to
the target against the number of instruments.

    python benchmarks/fleet_figure.py JSON [JSON ...] --out PATH [--titles "A,B"]

Each JSON is one setting written by ``benchmarks/fleet.py``. Its panel shows, per design, the
median over seeds of the RMSE of the last model made by each wall time (simulated s; a seed with
no model yet counts as the worst), shaded between the quartiles, and the target as a dashed line.
The last panel shows, per setting, the median over seeds of the wall time to the target as a
multiple of one instrument's (``fleet k=1``, the same seed; BoTorch's own k=1 for BoTorch's),
against k: one campaign (solid), k independent campaigns pooled (dashed) and BoTorch with the
points in flight as pending (dash-dot, where measured), with perfect scaling 1/k (dotted).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))

from fleet import reference, time_to  # noqa: E402

GRID = 200  # wall times per panel


def error_at(record: dict, walls: np.ndarray) -> np.ndarray:
    """The RMSE (len(walls),) of the last model made by each wall time; NaN before the first."""
    made = np.asarray(record["wall_s"])
    errors = np.asarray(record["rmse"], dtype=np.float64)
    index = np.searchsorted(made, walls, side="right") - 1
    return np.where(index >= 0, errors[np.clip(index, 0, None)], np.nan)


def quartile_curves(records: list, walls: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Median, first and third quartile over seeds at each wall time (no model yet: the worst)."""
    stack = np.nan_to_num(np.asarray([error_at(r, walls) for r in records]), nan=np.inf)
    with np.errstate(invalid="ignore"):  # quantiles between two infinite errors
        q = np.percentile(stack, [50, 25, 75], axis=0)
    return q[0], q[1], q[2]


FAMILIES = ("fleet", "independent", "botorch")  # fleet.py's designs, in the order they are drawn
STYLES = {"fleet": "-", "independent": "--", "botorch": "-."}


def family(name: str) -> str:
    """ "fleet", "independent" or "botorch" of a design "NAME k=K"."""
    return name.split(" ", 1)[0]


def k_of(name: str) -> int:
    return int(name.rsplit("=", 1)[1])


def ratio_to_one(records: dict, name: str, target: float) -> float:
    """Median over seeds of the wall time to the target over k=1's (``fleet.reference``: BoTorch's
    own for BoTorch's designs; NaN where half never reach)."""
    ones = {r["seed"]: time_to(r, target) for r in records[reference(name)]}
    ratios = [time_to(r, target) / ones[r["seed"]] for r in records[name] if r["seed"] in ones]
    v = np.nan_to_num(np.asarray(ratios, dtype=np.float64), nan=np.inf)
    return float(np.median(v)) if len(v) else float("nan")


def draw(paths: list[Path], titles: list[str], out: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(paths) + 1, figsize=(5.2 * (len(paths) + 1), 4.2))
    scaling = axes[-1]
    for setting, (ax, path, title) in enumerate(zip(axes, paths, titles)):
        data = json.loads(path.read_text())
        records, target = data["records"], data["settings"]["target"]
        end = max(r["wall_s"][-1] for recs in records.values() for r in recs)
        walls = np.linspace(0.0, end, GRID)
        for name in sorted(records, key=lambda n: (FAMILIES.index(family(n)), k_of(n))):
            median, low, high = quartile_curves(records[name], walls)
            style = STYLES[family(name)]
            (line,) = ax.plot(walls, median, style, label=name)
            ax.fill_between(walls, low, high, color=line.get_color(), alpha=0.15)
        ax.axhline(target, color="k", linestyle=":", linewidth=1, label=f"target {target:g}")
        ax.set_yscale("log")
        ax.set_xlabel("wall time (simulated s)")
        ax.set_ylabel("RMSE of f (median over seeds)")
        ax.set_title(f"{title}: {len(records['fleet k=1'])} seeds")
        ax.legend(fontsize=7)
        for kind, style, said in (
            ("fleet", "o-", "one campaign"),
            ("independent", "s--", "independent campaigns"),
            ("botorch", "^-.", "BoTorch, points in flight pending"),
        ):
            more = sorted((n for n in records if family(n) == kind and k_of(n) > 1), key=k_of)
            first = reference(f"{kind} k=1")
            if not more or first not in records:
                continue
            names = [first, *more]
            ratios = [ratio_to_one(records, n, target) for n in names]
            scaling.plot([k_of(n) for n in names], ratios, style, color=f"C{setting}", label=f"{title}: {said}")
    ks = np.array([1, 2, 4])
    scaling.plot(ks, 1 / ks, "k:", label="perfect scaling 1/k")
    scaling.set_xscale("log", base=2)
    scaling.set_yscale("log", base=2)
    scaling.set_xticks(ks, [str(k) for k in ks])
    ticks = [0.25, 0.35, 0.5, 0.75, 1.0]
    scaling.set_yticks(ticks, [f"{v:g}" for v in ticks])
    scaling.axhline(0.35, color="grey", linewidth=0.8, label="target at k=4: 0.35")
    scaling.set_xlabel("instruments k")
    scaling.set_ylabel("wall time to target / one instrument's (median)")
    scaling.set_title("wall time to the target RMSE")
    scaling.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out, dpi=110)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="benchmarks/fleet_figure.py", description=__doc__.split("\n\n")[0])
    parser.add_argument("json", nargs="+", type=Path)
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--titles", default=None, help="one per JSON, comma-separated (default: the file names)")
    args = parser.parse_args(argv)
    titles = args.titles.split(",") if args.titles else [p.stem for p in args.json]
    if len(titles) != len(args.json):
        parser.error(f"--titles: {len(titles)} titles for {len(args.json)} JSONs")
    draw(args.json, titles, args.out)
    print(args.out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
