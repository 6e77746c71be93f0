"""Spending a fixed instrument-time budget: the reconstruction error of f against cumulative time.

    python benchmarks/budget.py [--config PATH] [--budget S] [--overhead S] [--seeds 20]
                                [--designs NAMES] [--json PATH] [--figure PATH] [--report]

Every design runs the configuration with ``schedule.budget_s`` = --budget, ``point_overhead_s``
= --overhead (default: the config's own) and no step limit, for each seed:

- "reward", "double": the paper's two policies (and shot schedule);
- six fixed designs (five where a log-spaced t and t* take the same grid t), "fixed t=<t>": the
  reward-driven policy with every point at one t and ``shots_after`` shots (at least 2) from the
  first point on (with no t to learn, no point needs
  the 30 shots), at five log-spaced t across [t_min, t_max] (``np.geomspace``) and at t*, whose
  name ends in " (t*)" (t*(law), from the simulator's own noise law and the configured reward:
  see ``benchmarks/_tstar.py``). <t> is the nominal t in s to 4 significant digits, trailing
  zeros dropped, never an exponent: for Forrester's [0.2, 10] s "fixed t=0.2", "fixed t=0.5318",
  "fixed t=1.414", "fixed t=3.761", "fixed t=10" and "fixed t=2.512 (t*)". A campaign measures
  only at the config's t grid (``acquisition.fixed_t`` takes the grid's nearest entry); the output
  says which grid t each fixed design used where it is not the nominal one. "--designs fixed"
  selects every fixed design;
- "info_rate": ``acquisition.policy: info_rate`` (``noisebo.acquisition.information``);
- "budget cold": ``schedule.mode: budget`` (no dedicated noise measurements: every point takes
  ``shots_after`` shots and the noise model learns from their replicate scatter), the config's
  policy, no profile;
- "budget info_rate": the budget mode with ``acquisition.policy: info_rate`` (the most reduction
  of f's integrated variance per second), no profile;
- "budget informative": the budget mode with ``schedule.convergence: posterior`` (5 %) and
  ``noise_t: informative`` (until the 95 % interval of t* is within 5 %, each point measures at
  the t that narrows it most per second, keeping the policy's x), the config's policy, no profile;
- "budget info_rate informative": the same with ``acquisition.policy: info_rate``;
- "budget valued": the budget mode with ``schedule.noise_t: valued`` (a point leaves the policy's
  t where what its noise measurement teaches about t* is worth more to the later points than the
  reward it loses), the config's policy, no profile;
- "budget warm": the budget mode with ``noise_model.profile``: --profile, or else the profile an
  earlier run kept beside --json, or else one made here by ``noisebo noise-profile`` from 3
  campaigns of the paper's protocol (15 steps) on the same instrument and settings with seeds
  1000-1002, none of the benchmark's seeds, and kept there (the output says which); a --profile of
  another driver or other settings is used with ``profile_check: false``;
- "budget warm informative": the same profile with the posterior rule and informative noise points
  of "budget informative" (a profile that leaves t* wider than 5 % is narrowed by the campaign's own
  noise points);
- "budget warm info_rate": the same profile with ``acquisition.policy: info_rate`` and every
  seed point at t_min (``schedule.seed_t_scale: shortest``: the profile gives the noise law that
  seeds spread over t would pay to learn);
- "gpcam": the peer gpCAM (``benchmarks/_gpcam.py``: how it is set up and why that is fair);
- "botorch cost-aware", "botorch multi-fidelity": the peer BoTorch, its two documented ways of
  making a measurement's cost part of the decision (``benchmarks/_botorch.py``: how each is set
  up, why that is fair, and what each assumes that the instrument does not);
  the peers run when the optional extra is installed (``pip install 'noisebo[peers]'``); the
  output says so when one is not.

A design's name is the same everywhere: in --designs, in the output and as the key of the JSON's
``records``; a fixed design's depends on the config (its t range and t*), so --help describes them
and an unknown name is refused, naming every known one, once the config is read. A JSON written
with the earlier fixed designs ("fixed t_min", "fixed t*", "fixed t_max": the same campaigns as
"fixed t=<t_min>", "fixed t=<t*> (t*)", "fixed t=<t_max>") is read under the new names, taken
from the t range and t* stored in that JSON.

The table's last row, "best fixed t (in hindsight)", is at each checkpoint the lowest median
RMSE of the fixed designs reported (and which t it was), chosen after the fact: no campaign
could have known which t to fix; its time to the target is the least median time among the
fixed designs every seed of which reaches it.

After every decision it scores the model that decision was made with (the GP mean on the x grid,
interpolated to 200 evenly spaced positions for one axis) against the simulator's truth, beside
the instrument time spent when it was made, and at the end the final model. It prints, per
design, the median RMSE [IQR] once a given time is spent (the last model made within it; each
--at time once, those past --budget left out), the median time to first reach --target (default:
2 % of the range of the true f over the x grid; the output says which) when every seed reaches it, and the final predicted t
against t*(law) (and against t*(x-avg) too where the simulator's noise depends on x and the two
differ; the output names both); then each design's median as a multiple of the best fixed t in
hindsight's at each checkpoint, and the targets' verdicts for "budget cold" and "budget warm"
against the fixed designs and gpCAM, those present (``benchmarks/_targets.py``: which targets, how
they are judged); and plots the median curves with their IQR (--figure). A seed still measuring its
seed points has no model yet: it counts as the worst error, so a median needs half the seeds to
have one ("-" where fewer do). Results are written to --json after every seed, and a run given
the same --json measures only the seeds it lacks: a long run interrupted keeps what it has
measured. A --json measured with another instrument, space, budget or overhead is refused (its
seeds would be mixed with these). A warm design's seeds say what became of the profile's prior
(kept at every step, or dropped at which step) in the progress, the JSON (``profile``) and the
report; the warm design's profile campaigns, when made here, print their progress.
"""

from __future__ import annotations

import noisebo.cli  # noqa: F401 - first: one OpenBLAS thread for this process, before numpy loads (as the command line)
import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))  # the shared helpers (_config, _tstar)

import _targets  # noqa: E402
from _config import Parser, benchmark_config, refuse  # noqa: E402
from _tstar import LAW, X_AVG, describe, differ, t_stars  # noqa: E402

from noisebo.campaign.driver import run_campaign  # noqa: E402
from noisebo.metrics import median_iqr, relative_error, rmse  # noqa: E402
from noisebo.models.grids import grids  # noqa: E402
from noisebo.registry import paper_policies  # noqa: E402

FIXED = "fixed"  # in --designs: every fixed design
FIXED_PREFIX = "fixed t="
STAR_TAG = " (t*)"
N_LOG_SPACED = 5
INFO_RATE = "info_rate"
COLD, WARM, GPCAM, BUDGET_RATE = "budget cold", "budget warm", "gpcam", "budget info_rate"
BOTORCH_COST_AWARE, BOTORCH_MULTI_FIDELITY = "botorch cost-aware", "botorch multi-fidelity"
# The peers: name -> (module in benchmarks/, its run function); each module has available().
PEERS = {
    GPCAM: ("_gpcam", "run_gpcam"),
    BOTORCH_COST_AWARE: ("_botorch", "run_cost_aware"),
    BOTORCH_MULTI_FIDELITY: ("_botorch", "run_multi_fidelity"),
}
VALUED, INFORMATIVE = "budget valued", "budget informative"
RATE_INFORMATIVE = "budget info_rate informative"
WARM_INFORMATIVE = "budget warm informative"
WARM_RATE = "budget warm info_rate"
TARGET_OF_RANGE = 0.02  # the default --target: this fraction of the range of the true f on the x grid
PROFILE_SEEDS = (1000, 1001, 1002)  # the warm design's profile campaigns: none of the benchmark's seeds
# What --help lists: a fixed design's name depends on the config (its t range and t*).
DESIGNS = (
    *paper_policies(),
    FIXED_PREFIX + "<t>",
    FIXED_PREFIX + "<t*>" + STAR_TAG,
    FIXED,
    INFO_RATE,
    COLD,
    BUDGET_RATE,
    INFORMATIVE,
    RATE_INFORMATIVE,
    VALUED,
    WARM,
    WARM_INFORMATIVE,
    WARM_RATE,
    *PEERS,
)
RENAMED = {"info rate": INFO_RATE}  # a JSON written before the names were one spelling
BEST_FIXED = "best fixed t (in hindsight)"


def t_label(t: float) -> str:
    """A t (s) in a design's name: 4 significant digits, trailing zeros dropped, no exponent
    (0.2, 0.5318, 1.414, 10, 2.512)."""
    return np.format_float_positional(float(f"{float(t):.4g}"), trim="-")


def fixed_name(t: float, star: bool = False) -> str:
    return f"{FIXED_PREFIX}{t_label(t)}{STAR_TAG if star else ''}"


def is_fixed(name: str) -> bool:
    return name.startswith(FIXED_PREFIX)


def fixed_designs(t_min: float, t_max: float, t_star: float, on_grid=lambda t: t) -> dict[str, float]:
    """{name: nominal t (s)} of the fixed designs, by t: five log-spaced t across [t_min, t_max]
    and t* (its name tagged " (t*)"); a log-spaced t that ``on_grid`` (the t a campaign measures
    at) puts where t*'s design measures is left out, as the same campaigns under another name."""
    star_at = on_grid(float(t_star))
    spaced = [float(t) for t in np.geomspace(t_min, t_max, N_LOG_SPACED) if on_grid(float(t)) != star_at]
    ts = [(t, False) for t in spaced] + [(float(t_star), True)]
    return {fixed_name(t, star): t for t, star in sorted(ts)}


def old_names(t_min: float, t_max: float, t_star: float | None) -> dict[str, str]:
    """The names of a JSON written before the fixed designs were named by their t -> today's."""
    out = {**RENAMED, "fixed t_min": fixed_name(t_min), "fixed t_max": fixed_name(t_max)}
    if t_star is not None:
        out["fixed t*"] = fixed_name(t_star, star=True)
    return out


def design_names(text: str) -> list[str]:
    """--designs: comma-separated names (checked against the config's designs by ``resolve``)."""
    names = [n.strip() for n in text.split(",") if n.strip()]
    if not names:
        raise argparse.ArgumentTypeError(f"no design in {text!r}; known: {', '.join(DESIGNS)}")
    return list(dict.fromkeys(names))


def resolve(names: list[str], known: list[str]) -> tuple[list[str], list[str]]:
    """(designs, unknown names): "fixed" expanded to every fixed design of ``known``, in place."""
    out, unknown = [], []
    for name in names:
        if name == FIXED:
            out += [k for k in known if is_fixed(k)]
        elif name in known:
            out.append(name)
        else:
            unknown.append(name)
    return list(dict.fromkeys(out)), unknown


NO_STEP_LIMIT = 1_000_000


def grid_t(config, t: float) -> float:
    """The t a fixed design measures at: the config's t-grid entry nearest t, as
    ``acquisition.fixed_t`` takes it (``noisebo.acquisition.proposal._allowed_t``)."""
    g = grids(config).t
    return float(g[int(np.argmin(np.abs(g - t)))])


BUDGET_MODE = {"mode": "budget"}
LEARNS_T = {**BUDGET_MODE, "convergence": "posterior", "t_interval_rel": 0.05, "noise_t": "informative"}
# The budget designs without a profile: name -> (schedule, acquisition overrides).
BUDGET_DESIGNS = {
    COLD: (BUDGET_MODE, {}),
    BUDGET_RATE: (BUDGET_MODE, {"policy": INFO_RATE}),
    INFORMATIVE: (LEARNS_T, {}),
    RATE_INFORMATIVE: (LEARNS_T, {"policy": INFO_RATE}),
    VALUED: ({**BUDGET_MODE, "noise_t": "valued"}, {}),
}
# The designs recommended for the best map of f within a budget, each with its target against the
# best fixed t in hindsight (a multiple of it, at every checkpoint): cold, and from a noise profile.
MAPPING = {BUDGET_RATE: _targets.MAP_WITHIN_BEST, WARM_RATE: 1.0}
# The budget designs that start from a noise profile: name -> (schedule, acquisition overrides).
WARM_DESIGNS = {
    WARM: (BUDGET_MODE, {}),
    WARM_INFORMATIVE: (LEARNS_T, {}),
    WARM_RATE: ({**BUDGET_MODE, "seed_t_scale": "shortest"}, {"policy": INFO_RATE}),
}


def design_config(base, name: str, fixed: dict[str, float], profile=None):
    if name in BUDGET_DESIGNS:
        schedule, acquisition = BUDGET_DESIGNS[name]
        return base.with_overrides(schedule=schedule, acquisition=acquisition)
    if name in WARM_DESIGNS:
        schedule, acquisition = WARM_DESIGNS[name]
        return base.with_overrides(
            schedule=schedule,
            acquisition=acquisition,
            noise_model={"profile": profile.model_dump(mode="json"), "profile_check": describes(profile, base)},
        )
    if name in paper_policies():
        return base.with_overrides(acquisition={"policy": name})
    if name in PEERS:
        return base  # the peer reads the instrument, space, budget and shots_after from it
    if name == INFO_RATE:
        return base.with_overrides(acquisition={"policy": INFO_RATE})
    t = fixed[name]  # nominal: the campaign takes the t grid's nearest entry
    after = base.schedule.shots_after  # no t to learn: every point gets the few shots a converged campaign takes
    return base.with_overrides(
        acquisition={"policy": "reward", "fixed_t": float(t)},
        schedule={"shots_before": max(after, 2), "shots_after": after},
    )


def describes(profile, base) -> bool:
    """Whether ``profile`` was made with ``base``'s driver and settings: the check a campaign
    makes of its profile (``instruments.registry.profile_problem``)."""
    from noisebo.instruments.registry import profile_problem

    checked = base.with_overrides(noise_model={"profile": profile.model_dump(mode="json"), "profile_check": True})
    return profile_problem(checked, base.instrument.settings) is None


def made_profile(base, folder: Path):
    """The warm design's profile: ``noisebo noise-profile`` of 3 finished campaigns of the paper's
    protocol (15 steps, no budget) on ``base``'s instrument and settings, seeds ``PROFILE_SEEDS``."""
    from noisebo.cli.noise_profile import make_profile
    from noisebo.instruments import build
    from noisebo.instruments.registry import driver_info
    from noisebo.campaign import driver, engine
    from noisebo.storage.recorder import Recorder

    paper = base.with_overrides(schedule={"mode": "paper", "budget_s": None, "n_steps": 15})
    files = []
    for i, seed in enumerate(PROFILE_SEEDS, 1):
        path = folder / f"profile_s{seed}.h5"
        if not path.exists():
            tick = time.perf_counter()
            print(
                f"profile campaign {i} of {len(PROFILE_SEEDS)} (seed {seed}) into {path} ...",
                file=sys.stderr,
                flush=True,
            )
            started = engine.new_campaign(paper, seed, driver_info(paper.instrument), {}, "2026-11-25T00:00:00+00:00")
            with Recorder.create(path, started) as recorder:
                driver.drive(recorder.state, build(paper.instrument), recorder.commit)
            print(f"profile campaign {i} done in {time.perf_counter() - tick:.0f} s", file=sys.stderr, flush=True)
        files.append(path)
    return make_profile(files)


def warm_profile(args, base):
    """(the warm design's profile, where it came from): --profile, or the one kept beside --json
    by an earlier run on the same driver and settings, or one made here (kept in a folder beside
    --json with its campaigns)."""
    import yaml

    from noisebo.cli.noise_profile import law_text
    from noisebo.config import read_profile
    from noisebo.models.profile import NoiseProfile

    def read(path: Path, what: str) -> NoiseProfile:
        return NoiseProfile.model_validate(read_profile(path, what))

    if args.profile is not None:
        profile = read(args.profile, "--profile")
        configs = ", ".join(sorted({c.config for c in profile.campaigns})) or "unnamed configs"
        same = (
            "the same driver and settings"
            if describes(profile, base)
            else "another driver or settings, used with profile_check: false"
        )
        return (
            profile,
            f"profile {args.profile} ({len(profile.campaigns)} campaigns of {configs} on {profile.driver.name}: {same})",
        )
    folder = (args.json.parent / f"{args.json.stem}_profile") if args.json else Path("budget_profile")
    kept = folder / "profile.yaml"
    if kept.exists():  # an earlier run's: the same profile, so its seeds are measured alike
        profile = read(kept, "the kept profile")
        if describes(profile, base):  # else another config's: made anew below
            return (
                profile,
                f"profile kept from an earlier run: {law_text(profile.model_dump(mode='json'))} ({kept}; remove it to make a new one)",
            )
    folder.mkdir(parents=True, exist_ok=True)
    profile = made_profile(base, folder)
    kept.write_text(yaml.safe_dump(profile.model_dump(mode="json"), sort_keys=False))
    return profile, (
        f"profile made here from 3 paper-protocol campaigns (15 steps) of {base.name} with the same "
        f"instrument and settings, seeds {PROFILE_SEEDS[0]}-{PROFILE_SEEDS[-1]}: "
        f"{law_text(profile.model_dump(mode='json'))} ({kept})"
    )


def measured_otherwise(kept: dict | None, base) -> str | None:
    """What of the instrument, the space, the budget and the per-point overhead differs between the
    config a --json was measured with (``kept``) and ``base``: None where nothing does."""
    if not kept:
        return None
    now = base.model_dump(mode="json")
    differ = [k for k in ("instrument", "space") if kept.get(k) != now[k]]
    differ += [k for k in ("budget_s", "point_overhead_s") if kept.get("schedule", {}).get(k) != now["schedule"][k]]
    return ", ".join(differ) or None


def default_target(config, instrument, given: float | None) -> tuple[float, str]:
    """(the target RMSE, a line saying where it came from): --target, or ``TARGET_OF_RANGE`` of
    the range of the simulator's f over the config's x grid."""
    if given is not None:
        return given, f"target RMSE {given:g} (--target)"
    truth = np.asarray(instrument.truth(np.asarray(grids(config).x).reshape(-1, config.space.dimensions)))
    span = float(truth.max() - truth.min())
    target = float(f"{TARGET_OF_RANGE * span:.2g}")
    return (
        target,
        f"target RMSE {target:g}: {TARGET_OF_RANGE * 100:g} % of the range of f over the x grid ({span:.4g}); --target sets another",
    )


def scorer(config, instrument):
    """f_mean on the x grid -> RMSE against the truth (200 positions for one axis)."""
    g = grids(config)
    if config.space.dimensions == 1:
        x_eval = np.linspace(config.space.x_min, config.space.x_max, 200)
        truth = instrument.truth(x_eval[:, None])
        return lambda f_mean: rmse(np.interp(x_eval, g.x, f_mean), truth)
    truth = instrument.truth(g.x)
    return lambda f_mean: rmse(np.asarray(f_mean), truth)


def run_one(config, instrument, seed: int, score, t_star: float) -> dict:
    started = time.perf_counter()
    spent_at = []  # instrument time spent when each decision was made

    def on_commit(state, events):
        if any(type(e).__name__ == "Decided" for e in events):
            spent_at.append(state.spent_s)

    result = run_campaign(config, instrument, seed, on_commit=on_commit)
    final = result.final
    times = list(spent_at) + [final.spent_s]
    summary = final.summary
    errors = [score(d.f_mean) for d in final.decisions] + [score(summary.f_mean) if summary else float("nan")]
    return {
        "seed": seed,
        "times_s": [float(v) for v in times],
        "rmse": [float(v) for v in errors],
        "points": len(final.points),
        "status": final.status.value,
        "spent_s": float(final.spent_s),
        "t_opt": float(summary.t_opt) if summary else float("nan"),
        "t_rel_error": relative_error(summary.t_opt, t_star) if summary else float("nan"),
        "shots": [int(d.shots) for d in final.decisions],
        "t": [float(d.t) for d in final.decisions],
        "latency_s": float(np.median(result.latencies_s[1:])) if len(result.latencies_s) > 1 else float("nan"),
        "wall_s": time.perf_counter() - started,
        **({"profile": prior_fate(final)} if config.noise_model.profile is not None else {}),
    }


def prior_fate(final) -> dict:
    """What happened to a warm campaign's noise profile: at how many BO steps its prior was in use,
    the step it was dropped at (None: kept throughout), and the smallest posterior predictive p of
    the replicate scatter under it."""
    decisions = final.decisions
    return {
        "steps_in_use": sum(bool(d.profile_in_use) for d in decisions),
        "steps": len(decisions),
        "dropped_at_step": final.data.profile_dropped_step,
        "min_p": float(min((d.profile_p for d in decisions), default=float("nan"))),
    }


def prior_lines(records: dict) -> list[str]:
    """For each design whose campaigns had a noise profile: in how many seeds it was kept, and
    where it was dropped otherwise (records measured before this was kept say nothing)."""
    lines = []
    for name, recs in records.items():
        fates = [r["profile"] for r in recs if "profile" in r]
        if not fates:
            continue
        kept = sum(f["dropped_at_step"] is None for f in fates)
        dropped = sorted(f["dropped_at_step"] for f in fates if f["dropped_at_step"] is not None)
        where = f"; dropped at step {', '.join(str(k) for k in dropped)} in the others" if dropped else ""
        lines.append(f"{name}: the noise profile's prior was kept throughout in {kept} of {len(fates)} seeds{where}")
    if lines:
        lines.insert(0, "")
    return lines


def prior_said(fate: dict) -> str:
    if fate["dropped_at_step"] is None:
        return f"profile kept at all {fate['steps']} steps (smallest p {fate['min_p']:.2g})"
    return (
        f"profile dropped at step {fate['dropped_at_step']} (in use at {fate['steps_in_use']} of {fate['steps']} steps)"
    )


def rmse_at(record: dict, budget: float) -> float:
    inside = [e for t, e in zip(record["times_s"], record["rmse"]) if t <= budget + 1e-9]
    return inside[-1] if inside else float("nan")


def time_to(record: dict, target: float) -> float:
    return next((t for t, e in zip(record["times_s"], record["rmse"]) if e <= target), float("nan"))


NO_MODEL = 1e300  # a seed with no model yet (still measuring its seed points) counts as the worst error


def quartiles(values) -> tuple[float, float, float]:
    """Median, first and third quartile over seeds of errors, NaN (no model yet) counting as
    worse than any: inf where more than that share of the seeds has no model."""
    v = np.nan_to_num(np.asarray(values, dtype=np.float64), nan=NO_MODEL)
    q = np.percentile(v, [50, 25, 75], axis=0)
    return tuple(np.where(q >= NO_MODEL / 10, np.inf, q))


def best_in_hindsight(records: dict, at) -> list[tuple[float, str] | None]:
    """At each time in ``at``: (the lowest median RMSE over the fixed designs in ``records``, that
    design's name), None where no fixed design has a median (half its seeds with a model)."""
    medians = {
        name: [quartiles([rmse_at(r, b) for r in recs])[0] for b in at]
        for name, recs in records.items()
        if is_fixed(name) and recs
    }
    out = []
    for i in range(len(at)):
        finite = [(m[i], name) for name, m in medians.items() if np.isfinite(m[i])]
        out.append(min(finite) if finite else None)
    return out


def medians(recs: list, at) -> list[float]:
    """The median RMSE over seeds at each time in ``at``: inf where half the seeds have no model."""
    return [float(quartiles([rmse_at(r, b) for r in recs])[0]) for b in at]


def median_time(recs: list, target: float) -> float:
    """The median time (s) to first reach ``target``, a seed that never does counting as never (inf)."""
    return float(np.median([np.inf if np.isnan(v) else v for v in (time_to(r, target) for r in recs)]))


def fixed_baseline(records: dict, at) -> tuple[list[str], list[float]]:
    """The fixed designs with seeds in ``records`` and, at each time in ``at``, the best fixed t in
    hindsight's median (NaN where none has one; empty with fewer than two fixed designs)."""
    fixed_shown = [n for n, recs in records.items() if is_fixed(n) and recs]
    if len(fixed_shown) < 2:
        return fixed_shown, []
    found = best_in_hindsight({n: records[n] for n in fixed_shown}, at)
    return fixed_shown, [np.nan if b is None else b[0] for b in found]


def against_best(records: dict, at) -> list[str]:
    """Markdown rows: each learning design's median over the best fixed t in hindsight's."""
    fixed_shown, best = fixed_baseline(records, at)
    if len(fixed_shown) < 2:
        return []
    rows = ["| design | " + " | ".join(f"{v:g} s" for v in at) + " |", "|---" * (len(at) + 1) + "|"]
    for name, recs in records.items():
        if recs and not is_fixed(name):
            cells = ["-" if not np.isfinite(r) else f"{r:.2f}" for r in _targets.ratios(medians(recs, at), best)]
            rows.append(f"| {name} | " + " | ".join(cells) + " |")
    return rows


def target_lines(records: dict, at, target: float, t_star_name: str, t_star: float) -> list[str]:
    """The targets' verdicts (``benchmarks/_targets.py``) for the cold and warm designs present,
    each against the fixed designs and the peers where those are present too."""
    present = {n: r for n, r in records.items() if r}
    learners = [n for n in (WARM, COLD) if n in present]
    fixed_shown, best = fixed_baseline(present, at)
    lines = mapping_lines(present, at, best if len(fixed_shown) > 1 else None)
    if not learners:
        return lines
    mine = {n: medians(present[n], at) for n in learners}
    if len(fixed_shown) > 1:
        typical = _targets.median_of_designs([medians(present[n], at) for n in fixed_shown])
        if WARM in mine:
            lines.append(
                f"- {WARM} at or below the best fixed t in hindsight at every checkpoint: {_targets.verdict(mine[WARM], best, at)}"
            )
        if COLD in mine:
            within = _targets.scaled(best, _targets.WITHIN_BEST)
            lines.append(
                f"- {COLD} within 10 % of the best fixed t in hindsight at every checkpoint: {_targets.verdict(mine[COLD], within, at)}"
            )
        bound = _targets.scaled(typical, _targets.OF_MEDIAN_FIXED)
        shown = ", ".join(f"{v:.4g}" for v in bound)
        for n in learners:
            lines.append(
                f"- {n} at most 0.8 x the median of the {len(fixed_shown)} fixed designs ({shown}): "
                + _targets.verdict(mine[n], bound, at)
            )
    for name in [n for n in PEERS if n in present and COLD in mine]:
        theirs = medians(present[name], at)
        lines.append(
            f"- {COLD} below {name} at every checkpoint: {_targets.verdict(mine[COLD], theirs, at, strict=True)}"
        )
    times = ", ".join(
        f"{n} {'never' if not np.isfinite(m) else f'{m:.0f} s'}"
        for n in learners
        for m in [median_time(present[n], target)]
    )
    lines.append(
        f"- time to RMSE {target:g}, median over seeds (a seed that never reaches it counts as never): {times}"
    )
    judged = "; ".join(
        f"{n} " + _targets.t_verdict([relative_error(r["t_opt"], t_star) for r in present[n]]) for n in learners
    )
    lines.append(f"- final t within 5 % of {t_star_name} in 95 % of seeds: {judged}")
    latency = ", ".join(f"{n} {_latency(present[n])}" for n in learners)
    lines.append(
        f"- decision latency, the median over seeds of each seed's median (as loaded as the machine was): {latency}"
    )
    return lines


def mapping_lines(present: dict, at, best: list[float] | None) -> list[str]:
    """The targets of the designs recommended for the best map of f (``MAPPING``): against the
    peers present and, where ``best`` (the best fixed t in hindsight's medians) is given, against it."""
    lines = []
    for name, within in MAPPING.items():
        if name not in present:
            continue
        mine = medians(present[name], at)
        for peer_name in [n for n in PEERS if n in present]:
            theirs = medians(present[peer_name], at)
            lines.append(
                f"- {name} below {peer_name} at every checkpoint: {_targets.verdict(mine, theirs, at, strict=True)}"
            )
        if best is None:
            continue
        said = "at or below" if within == 1 else f"within {100 * (within - 1):.0f} % of"
        lines.append(
            f"- {name} {said} the best fixed t in hindsight at every checkpoint: "
            + _targets.verdict(mine, _targets.scaled(best, within), at)
        )
        lines.append(
            f"- {name} at most {_targets.MAP_STRETCH:g} x the best fixed t in hindsight (stretch): "
            + _targets.verdict(mine, _targets.scaled(best, _targets.MAP_STRETCH), at)
        )
    return lines


def _latency(recs: list) -> str:
    values = [r["latency_s"] for r in recs if np.isfinite(r.get("latency_s", np.nan))]
    return f"{np.median(values):.3f} s" if values else "not recorded"


def figure(records: dict, budget: float, path: Path, title: str) -> None:
    from matplotlib.figure import Figure

    grid = np.linspace(0.0, budget, 181)[1:]
    fig = Figure(figsize=(8, 5), layout="constrained")
    ax = fig.subplots()
    from matplotlib import colormaps

    palette = colormaps["tab20"].colors  # 20 distinct colours: more designs than the default cycle's 10
    for k, (name, recs) in enumerate(records.items()):
        curves = np.array([[rmse_at(r, b) for b in grid] for r in recs])
        mid, lo, hi = quartiles(curves)
        ok = np.isfinite(mid)  # where at least half the seeds have a model
        if not ok.any():
            continue
        style = {"ls": ":", "lw": 1.2} if is_fixed(name) else {"ls": "-", "lw": 1.8}  # fixed designs dotted
        (line,) = ax.plot(grid[ok], mid[ok], label=name, color=palette[(2 * k) % 20 + (2 * k // 20) % 2], **style)
        ax.fill_between(grid[ok], lo[ok], np.where(np.isfinite(hi), hi, np.nan)[ok], color=line.get_color(), alpha=0.15)
    best = best_in_hindsight(records, grid)
    if sum(is_fixed(n) for n in records) > 1 and any(b is not None for b in best):
        ax.plot(grid, [np.nan if b is None else b[0] for b in best], "k--", lw=1.0, label=BEST_FIXED)
    ax.set(xlabel="instrument time spent (s)", ylabel="RMSE of f (median, IQR shaded)", title=title, yscale="log")
    ax.legend(fontsize=8)
    fig.savefig(path, dpi=120)


def build_parser() -> Parser:
    """The benchmark's command line."""
    parser = Parser(prog=Path(__file__).name, description=__doc__.split("\n")[0])
    parser.add_argument("--config", default=str(ROOT / "data" / "configs" / "forrester.yaml"))
    parser.add_argument("--budget", type=float, default=900.0)
    parser.add_argument(
        "--overhead",
        type=float,
        default=None,
        help="instrument time (s) per point beside its shots (default: the config's schedule.point_overhead_s)",
    )
    parser.add_argument("--seeds", type=int, default=20)
    parser.add_argument("--first-seed", type=int, default=0)
    parser.add_argument(
        "--designs",
        type=design_names,
        default=None,
        metavar="NAME[,NAME...]",
        help="comma-separated designs, quoted where a name has a space (default: all): "
        f"{', '.join(DESIGNS)}. <t>: five log-spaced t (s) across [t_min, t_max], <t*>: "
        "t*(law), in s to 4 significant digits, e.g. for [0.2, 10] s 'fixed t=0.2', "
        "'fixed t=0.5318', 'fixed t=1.414', 'fixed t=3.761', 'fixed t=10', "
        "'fixed t=2.512 (t*)'; 'fixed': all six. An unknown name is refused "
        "naming the config's designs",
    )
    parser.add_argument("--at", default="100,200,300,500,860", help="times (s) to report the RMSE at")
    parser.add_argument(
        "--target",
        type=float,
        default=None,
        help=f"the RMSE whose time to reach is reported (default: {TARGET_OF_RANGE * 100:g} %% of the range of the "
        "simulator's f over the config's x grid; the output says which)",
    )
    parser.add_argument("--json", type=Path, default=None)
    parser.add_argument("--figure", type=Path, default=None)
    parser.add_argument(
        "--profile",
        type=Path,
        default=None,
        metavar="PROFILE.yaml",
        help="the warm design's noise profile (default: the one an earlier run kept beside --json, "
        f"or one made here from 3 paper-protocol campaigns, seeds {PROFILE_SEEDS[0]}-{PROFILE_SEEDS[-1]}, "
        "and kept there)",
    )
    parser.add_argument(
        "--report", action="store_true", help="measure nothing: report every seed --json holds for each design"
    )
    return parser


def save(path: Path, base, stars: dict, fixed: dict, on_grid: dict, records: dict) -> None:
    """Everything measured so far, written after every seed: a long run interrupted keeps it."""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(
        json.dumps(
            {
                "config": base.model_dump(mode="json"),
                "t_star": stars[LAW],
                "t_star_definition": LAW,
                "t_stars": stars,
                "fixed_t": {n: {"nominal_s": t, "grid_s": on_grid[n]} for n, t in fixed.items()},
                "records": records,
            },
            default=float,
        )
    )


def peer(name: str):
    """The peer design ``name``'s (available, run) functions, from its module in benchmarks/."""
    import importlib

    module_name, run = PEERS[name]
    module = importlib.import_module(module_name)
    return module.available, getattr(module, run)


def measure(name: str, config, instrument, wanted: list[int], done: dict, args, score, stars: dict, save_all) -> list:
    """``name``'s record of every seed in ``wanted``: those ``done`` holds, the others run here
    (each saved through ``save_all`` as soon as it is measured)."""
    kept = {r["seed"]: r for r in done.get("records", {}).get(name, []) if r["seed"] in wanted}
    if kept:
        print(f"{name}: {len(kept)} seeds kept from {args.json}", file=sys.stderr, flush=True)
    run = peer(name)[1] if name in PEERS else run_one
    for seed in wanted:
        if seed in kept:
            continue
        rec = run(config, instrument, seed, score, stars[LAW])
        kept[seed] = rec
        final = f"{rec['rmse'][-1]:.3f}" if rec["rmse"] else "- (no model: the seed points took the budget)"
        print(
            f"{name:>12} seed {seed:3d}: {rec['points']} points, {rec['spent_s']:.0f} s, final RMSE "
            f"{final}, t {rec['t_opt']:.3f} s, decision {rec['latency_s']:.3f} s, wall {rec['wall_s']:.0f} s"
            + (f"; {prior_said(rec['profile'])}" if "profile" in rec else ""),
            file=sys.stderr,
            flush=True,
        )
        if args.json:
            done.setdefault("records", {})[name] = sorted(
                {**{r["seed"]: r for r in done.get("records", {}).get(name, [])}, **kept}.values(),
                key=lambda r: r["seed"],
            )
            save_all(done["records"])
    return [kept[seed] for seed in wanted]


def design_row(name: str, recs: list, at: list[float], target: float, stars: dict, against: list[str]) -> str:
    """The table's row of one design: the RMSE at each time, the time to ``target``, the points,
    and how close its final t came to each t* of ``against``."""
    cells = []
    for b in at:
        values = [rmse_at(r, b) for r in recs]
        m, lo, hi = quartiles(values)
        cells.append(
            "-"
            if not np.isfinite(m)
            else f"{m:.3f} [{lo:.3f}, {'-' if not np.isfinite(hi) else f'{hi:.3f}'}]"
            + ("" if all(np.isfinite(values)) else f" ({sum(np.isfinite(values))} with a model)")
        )
    reach = [time_to(r, target) for r in recs]
    reached = [v for v in reach if np.isfinite(v)]
    when = f"{np.median(reach):.0f}" if len(reached) == len(reach) else f"{len(reached)} of {len(reach)} reach it"
    t_cells = []
    for star in against:
        errors = [relative_error(r["t_opt"], stars[star]) for r in recs]
        t_cells.append(f"{sum(e <= 0.05 for e in errors)} of {len(recs)} | {100 * median_iqr(errors)[0]:.1f} %")
    return (
        f"| {name} ({len(recs)} seeds) | "
        + " | ".join(cells)
        + f" | {when} | {np.median([r['points'] for r in recs]):.0f} | "
        + " | ".join(t_cells)
        + " |"
    )


def best_fixed_rows(records: dict, at: list[float], target: float, against: list[str]) -> list[str]:
    """The best fixed t in hindsight's row and its note (none with fewer than two fixed designs)."""
    fixed_shown = [n for n, recs in records.items() if is_fixed(n) and recs]
    if len(fixed_shown) < 2:
        return []
    best = best_in_hindsight({n: records[n] for n in fixed_shown}, at)
    cells = ["-" if b is None else f"{b[0]:.3f} ({b[1]})" for b in best]
    reach = []
    for n in fixed_shown:
        times = [time_to(r, target) for r in records[n]]
        if all(np.isfinite(times)):
            reach.append((float(np.median(times)), n))
    when = "-" if not reach else f"{min(reach)[0]:.0f} ({min(reach)[1]})"
    return [
        f"| {BEST_FIXED} | " + " | ".join(cells) + f" | {when} | - | " + " | ".join("- | -" for _ in against) + " |",
        f"\n{BEST_FIXED}: at each time the lowest median over the {len(fixed_shown)} fixed designs above "
        "(which one in brackets), chosen after the fact: no campaign could have known which t to fix.",
    ]


def print_table(records: dict, at: list[float], target: float, stars: dict, both: bool) -> None:
    """The RMSE table of every design with records, the best fixed t in hindsight, each design
    against it, and the verdict on each target."""
    print("RMSE of f once this much instrument time is spent, median [IQR] over seeds:\n")
    against = [LAW, X_AVG] if both else [LAW]
    print(
        "| design | "
        + " | ".join(f"{v:g} s" for v in at)
        + f" | time to RMSE {target:g} (s) | points | "
        + " | ".join(f"final t within 5 % of {name} | final t error vs {name}" for name in against)
        + " |"
    )
    print("|---" * (len(at) + 3 + 2 * len(against)) + "|")
    for name, recs in records.items():
        if recs:
            print(design_row(name, recs, at, target, stars, against))
    for line in best_fixed_rows(records, at, target, against):
        print(line)
    ratio_rows = against_best(records, at)
    if ratio_rows:
        print("\nEach design's median RMSE as a multiple of the best fixed t in hindsight's (below 1: lower):\n")
        print("\n".join(ratio_rows))
    verdicts = target_lines(records, at, target, LAW, stars[LAW])
    if verdicts:
        print("\nTargets, judged on the medians above:\n")
        print("\n".join(verdicts))


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    base, instrument = benchmark_config(
        parser,
        args.config,
        lambda c: c.with_overrides(
            schedule={
                "budget_s": args.budget,
                "point_overhead_s": c.schedule.point_overhead_s if args.overhead is None else args.overhead,
                "n_steps": NO_STEP_LIMIT,
            }
        ),
    )
    overhead = base.schedule.point_overhead_s
    target, target_said = default_target(base, instrument, args.target)
    stars = t_stars(base, instrument)
    t_star = stars[LAW]
    both = differ(stars)
    score = scorer(base, instrument)
    s = base.space
    fixed = fixed_designs(s.t_min, s.t_max, t_star, lambda t: grid_t(base, t))
    known = [*paper_policies(), *fixed, INFO_RATE, *BUDGET_DESIGNS, *WARM_DESIGNS, *PEERS]
    names, unknown = resolve(args.designs or known, known)
    if unknown:
        parser.error(
            f"argument --designs: unknown design {', '.join(repr(n) for n in unknown)}; "
            f"known: {', '.join([*known, FIXED])}"
        )
    at = sorted({float(v) for v in args.at.split(",") if v.strip() and float(v) < args.budget} | {args.budget})
    records: dict[str, list] = {}
    done = json.loads(args.json.read_text()) if args.json and args.json.exists() else {}
    other = measured_otherwise(done.get("config"), base)
    if other and not args.report:
        refuse(
            parser,
            f"{args.json} holds campaigns measured with other settings ({other}): its seeds would be mixed with these; "
            "give another --json (or the same settings)",
        )
    if "records" in done:  # earlier names, from the t range and t* that JSON was measured with
        space = done.get("config", {}).get("space", {})
        renamed = old_names(space.get("t_min", s.t_min), space.get("t_max", s.t_max), done.get("t_star", t_star))
        done["records"] = {renamed.get(k, k): v for k, v in done["records"].items()}
        if args.report and args.designs is None:  # what it holds, in the usual order, other configs' names last
            names = [n for n in names if n in done["records"]] + [k for k in done["records"] if k not in names]
    on_grid = {name: grid_t(base, t) for name, t in fixed.items()}
    snapped = [
        f"{name} at t = {on_grid[name]:.4g} s"
        for name in names
        if name in fixed and abs(on_grid[name] / fixed[name] - 1.0) > 1e-9
    ]
    wanted = list(range(args.first_seed, args.first_seed + args.seeds))
    notes = []
    for name in [n for n in names if n in PEERS and not args.report]:
        missing_peer = peer(name)[0]()
        if missing_peer is not None:
            names.remove(name)
            notes.append(f"{name}: not run: {missing_peer}")
    profile = None
    warm = [name for name in names if name in WARM_DESIGNS]
    if warm and (not args.report or args.profile is not None):  # a report names a given profile too
        profile, whence = warm_profile(args, base)
        notes.append(f"{', '.join(warm)}: {whence}")

    def save_all(measured: dict) -> None:
        save(args.json, base, stars, fixed, on_grid, measured)

    for name in names:
        if args.report:
            records[name] = done.get("records", {}).get(name, [])
            continue
        config = design_config(base, name, fixed, profile)
        records[name] = measure(name, config, instrument, wanted, done, args, score, stars, save_all)
    counts = sorted({len(r) for r in records.values() if r}) or [0]
    print(
        f"{base.name}: budget {args.budget:g} s, {overhead:g} s per point, "
        f"{'/'.join(str(c) for c in counts)} seeds per design; "
        f"{describe(stars, LAW + (f' and {X_AVG}' if both else ''))}"
    )
    for note in notes:
        print(note)
    missing = [n for n, r in records.items() if not r]
    if missing and args.report:
        print(f"Not in {args.json}: {', '.join(missing)}")
    if snapped:
        print(
            f"A fixed design measures at the nearest of the config's {s.n_t} grid t in [{s.t_min:g}, {s.t_max:g}] s: "
            + "; ".join(snapped)
        )
    print()
    print(target_said)
    print_table(records, at, target, stars, both)
    for line in prior_lines(records):
        print(line)
    if args.figure:
        figure(
            {n: r for n, r in records.items() if r},
            args.budget,
            args.figure,
            f"{base.name}: budget {args.budget:g} s, {'/'.join(str(c) for c in counts)} seeds",
        )
        print(f"\nwrote {args.figure}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
