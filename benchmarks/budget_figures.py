"""The budget benchmark's figures, one per question, from its shipped results (no campaign is run).

    python benchmarks/budget_figures.py [--results DIR] [--out DIR]

Reads ``budget_<setting>.json`` of each setting (Forrester; Forrester with A0 = 0.5, A1 = 1; the
PFM scan line; a line across the second scan; the 2-D PFM area; hetGP's test function; the second
scan's diagonal) from --results (default benchmarks/results) and writes one figure per question to
--out (default docs/images), each with one panel per setting and a few curves per panel:

- ``budget-learning-t.png``: does learning t beat a fixed t? (``budget cold``, ``budget warm``,
  the fixed design at t* and the best fixed t in hindsight);
- ``budget-peers.png``: how do the budget designs compare with the peers, gpCAM and BoTorch?
  (``budget cold``, ``budget info_rate``, ``gpcam``, ``botorch cost-aware``, ``botorch
  multi-fidelity`` and the best fixed t in hindsight);
- ``budget-variants.png``: which budget-mode variant? (``budget cold``, ``budget info_rate``,
  ``budget informative``, ``budget warm`` and the best fixed t in hindsight);
- ``budget-mapping.png``: which design maps f best for the time spent? (the designs recommended
  for it, ``budget info_rate`` and ``budget warm info_rate``, the peers that map best, ``gpcam``
  and ``botorch multi-fidelity``, and the best fixed t in hindsight).

Each curve is a design's median RMSE over its seeds against the instrument time spent, its
interquartile range shaded, computed as ``budget.py --figure`` computes its curves (the same
functions: the last model made within each time, a seed with no model yet counting as the worst
error, no curve where half the seeds have none). The best fixed t in hindsight is, at each time,
the lowest median of the fixed designs (``budget.best_in_hindsight``), drawn dashed with no
band: it is a choice made after the fact, not a design. A design a setting did not run is named in
its panel.
"""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))  # the budget benchmark and its shared helpers

import budget  # noqa: E402
from budget import (  # noqa: E402
    BEST_FIXED,
    BOTORCH_COST_AWARE,
    BOTORCH_MULTI_FIDELITY,
    BUDGET_RATE,
    COLD,
    GPCAM,
    INFORMATIVE,
    STAR_TAG,
    WARM,
    WARM_RATE,
    is_fixed,
)

AT_T_STAR = "fixed t at t*"  # the fixed design whose name ends in " (t*)": its t differs by setting


@dataclass(frozen=True)
class Setting:
    stem: str  # budget_<stem>.json
    title: str
    ylabel: str


@dataclass(frozen=True)
class Question:
    name: str  # budget-<name>.png
    title: str
    curves: tuple[str, ...]  # design names, BEST_FIXED or AT_T_STAR


SETTINGS = (
    Setting("forrester", "Forrester", "RMSE of f"),
    Setting("forrester_noise05", "Forrester, A0 = 0.5, A1 = 1", "RMSE of f"),
    Setting("pfm", "PFM scan line", "RMSE of the profile (pm)"),
    Setting("pfm_funakubo0001", "PFM, second scan", "RMSE of the profile (pm)"),
    Setting("pfm2d", "PFM area (2-D)", "RMSE of the map (pm)"),
    Setting("hetgp", "hetGP's test function", "RMSE of f"),
    Setting("pfm_funakubo0001_diagonal", "PFM, second scan's diagonal", "RMSE of the profile (pm)"),
)

QUESTIONS = (
    Question("learning-t", "Does learning t beat a fixed t?", (COLD, WARM, AT_T_STAR, BEST_FIXED)),
    Question(
        "peers",
        "How do the budget designs compare with the peers?",
        (COLD, BUDGET_RATE, GPCAM, BOTORCH_COST_AWARE, BOTORCH_MULTI_FIDELITY, BEST_FIXED),
    ),
    Question("variants", "Which budget-mode variant?", (COLD, BUDGET_RATE, INFORMATIVE, WARM, BEST_FIXED)),
    Question(
        "mapping",
        "Which design maps f best for the time spent?",
        (BUDGET_RATE, WARM_RATE, GPCAM, BOTORCH_MULTI_FIDELITY, BEST_FIXED),
    ),
)

# One look per curve in every figure, so a design reads the same from one question to the next.
STYLE = {
    COLD: {"color": "tab:blue", "ls": "-"},
    WARM: {"color": "tab:orange", "ls": "-"},
    BUDGET_RATE: {"color": "tab:green", "ls": "-"},
    WARM_RATE: {"color": "tab:olive", "ls": "-"},
    INFORMATIVE: {"color": "tab:purple", "ls": "-"},
    GPCAM: {"color": "tab:red", "ls": "-"},
    BOTORCH_COST_AWARE: {"color": "tab:brown", "ls": "-"},
    BOTORCH_MULTI_FIDELITY: {"color": "tab:pink", "ls": "-"},
    AT_T_STAR: {"color": "tab:gray", "ls": ":"},
    BEST_FIXED: {"color": "black", "ls": "--"},
}


@dataclass(frozen=True)
class Results:
    """One setting's ``budget.py --json`` file: its records under the designs' names (the fixed ones by t), its budget
    (s) and t* (s)."""

    records: dict[str, list]
    budget_s: float
    t_star: float


def load(path: Path) -> Results:
    done = json.loads(path.read_text())
    config = done["config"]
    space = config["space"]
    renamed = budget.old_names(space["t_min"], space["t_max"], done.get("t_star"))
    records = {renamed.get(name, name): recs for name, recs in done["records"].items() if recs}
    return Results(records, float(config["schedule"]["budget_s"]), float(done["t_star"]))


def time_grid(budget_s: float) -> np.ndarray:
    """The times the curves are drawn at: those of ``budget.py --figure``."""
    return np.linspace(0.0, budget_s, 181)[1:]


def band(recs: list, grid) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(median, first quartile, third quartile) of the seeds' RMSE at each time of ``grid``: inf where
    more than that share of the seeds has no model yet (``budget.quartiles``)."""
    values = np.array([[budget.rmse_at(r, b) for b in grid] for r in recs])
    mid, lo, hi = budget.quartiles(values)
    return np.asarray(mid), np.asarray(lo), np.asarray(hi)


def curves(records: dict[str, list], wanted, grid) -> dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """{curve: (median, lower, upper)} of each curve in ``wanted`` that ``records`` holds: a design's
    median and quartiles; the best fixed t in hindsight's lowest median of the fixed designs, NaN
    where none has a median, with no band (NaN)."""
    out = {}
    for name in wanted:
        if name == BEST_FIXED:
            fixed = {n: recs for n, recs in records.items() if is_fixed(n)}
            if len(fixed) < 2:
                continue
            best = np.array([np.nan if b is None else b[0] for b in budget.best_in_hindsight(fixed, grid)])
            out[name] = (best, np.full_like(best, np.nan), np.full_like(best, np.nan))
            continue
        found = [n for n in records if n.endswith(STAR_TAG)] if name == AT_T_STAR else [name]
        if found and found[0] in records:
            out[name] = band(records[found[0]], grid)
    return out


def draw(ax, drawn: dict, grid, title: str, ylabel: str, wanted=()) -> None:
    """One setting's panel: each curve's median (where finite) and its band, lightly shaded; the
    curves of ``wanted`` not in ``drawn`` named in a corner."""
    for name, (mid, lo, hi) in drawn.items():
        ok = np.isfinite(mid)
        style = STYLE.get(name, {})
        ax.plot(grid[ok], mid[ok], lw=1.8, label=name, gid=name, **style)
        shaded = ok & np.isfinite(lo)
        if shaded.any():
            upper = np.where(np.isfinite(hi), hi, np.nan)
            ax.fill_between(grid[shaded], lo[shaded], upper[shaded], color=style.get("color"), alpha=0.15, lw=0)
    missing = [n for n in wanted if n not in drawn]
    if missing:
        note = "not run here:\n" + "\n".join(missing)  # one per line: a list of two overran a panel
        ax.text(0.97, 0.96, note, transform=ax.transAxes, ha="right", va="top", fontsize=9, color="0.3")
    ax.set_title(title, fontsize=11)
    ax.set(xlabel="instrument time spent (s)", ylabel=ylabel, yscale="log", xlim=(0, grid[-1]))
    late = grid >= 0.15 * grid[-1]  # the first seconds' errors (a handful of points) would set the scale
    lows, highs = [], []
    for mid, _, hi in drawn.values():
        ok = np.isfinite(mid)
        if (ok & late).any():
            lows.append(np.min(mid[ok]))
            highs.append(np.max(np.where(np.isfinite(hi), hi, mid)[ok & late]))
    if lows:
        ax.set_ylim(0.85 * min(lows), 1.15 * max(highs))
    ax.yaxis.set_major_locator(LogLocator(subs=(1.0, 2.0, 3.0, 5.0)))
    ax.yaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))  # 0.2, 0.3, 0.5, 1, 2: no exponents
    ax.yaxis.set_minor_formatter(NullFormatter())
    ax.grid(True, which="both", color="0.9", lw=0.6)


def question_figure(question: Question, panels: list[tuple[Setting, Results, dict]]):
    """The question's figure: one panel per (setting, its results, its curves from ``curves``), the
    legend in a panel of its own."""
    from matplotlib.figure import Figure

    columns = 2  # read at the docs' width: two panels a row
    rows = -(-(len(panels) + 1) // columns)
    fig = Figure(figsize=(4.3 * columns, 3.2 * rows), layout="constrained")
    axes = fig.subplots(rows, columns, squeeze=False).ravel()
    handles: dict[str, object] = {}
    for ax, (setting, results, drawn) in zip(axes, panels):
        grid = time_grid(results.budget_s)
        seeds = "/".join(str(n) for n in sorted({len(r) for r in results.records.values()}))
        title = f"{setting.title}\n(t* = {budget.t_label(results.t_star)} s; {seeds} seeds)"
        draw(ax, {n: drawn[n] for n in question.curves if n in drawn}, grid, title, setting.ylabel, question.curves)
        for line in ax.get_lines():
            handles.setdefault(line.get_gid(), line)
    for ax in axes[len(panels) :]:
        ax.axis("off")
    names = [n for n in question.curves if n in handles]
    axes[len(panels)].legend(
        [handles[n] for n in names],
        names,
        loc="center left",
        fontsize=11,
        frameon=False,
        title="median over the seeds,\ninterquartile range shaded",
        title_fontsize=10,
        alignment="left",
    )
    fig.suptitle(question.title, fontsize=14)
    return fig


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog=Path(__file__).name, description=__doc__.split("\n")[0])
    parser.add_argument("--results", type=Path, default=ROOT / "benchmarks" / "results", help="where budget_*.json are")
    parser.add_argument("--out", type=Path, default=ROOT / "docs" / "images", help="where the figures are written")
    args = parser.parse_args(argv)
    wanted = list(dict.fromkeys(n for q in QUESTIONS for n in q.curves))
    panels = []
    for setting in SETTINGS:
        results = load(args.results / f"budget_{setting.stem}.json")
        panels.append((setting, results, curves(results.records, wanted, time_grid(results.budget_s))))
    args.out.mkdir(parents=True, exist_ok=True)
    from matplotlib import rc_context

    with rc_context({"font.size": 11}):  # read at the docs' width: larger than matplotlib's 10
        for question in QUESTIONS:
            path = args.out / f"budget-{question.name}.png"
            question_figure(question, panels).savefig(path, dpi=110)
            print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
