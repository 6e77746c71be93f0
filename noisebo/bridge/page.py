"""The operator's page, the bridge's ``/``: what the campaign is doing now (waiting for the
instrument PC, measuring a point's shot, deciding, or ended and why), progress (finished points
and their shots, failed attempts, instrument time, budget), whether the instrument PC is
connected, the model of f and the noise model so far as pictures, and the last points. Plain
HTML with inline SVG, nothing loaded from elsewhere, so it works offline; it reloads itself every
``REFRESH_S`` seconds while the campaign runs, and no longer once it has ended (the bridge stops
soon after, and a browser keeps the final page it loaded rather than showing an error).

What the page says of the campaign comes from one committed state (its phase is ``engine.ask``
of it, as the exchange's), so its parts never disagree; ``status`` gives only what the
exchange knows of the instrument PC. Units: x in the config's x units, t in s, values and noise
in f units.
"""

from __future__ import annotations

import html
import math
from typing import TYPE_CHECKING, Sequence

import numpy as np

from noisebo.bridge.wire import campaign_id
from noisebo.campaign import engine, instrument_budget
from noisebo.campaign.own_noise import own_data
from noisebo.events import DecisionDue, Done, Request, Status, Wait
from noisebo.storage.steps import shown as shown_step

if TYPE_CHECKING:
    from noisebo.campaign.engine import EngineState

REFRESH_S = 2
LAST_POINTS = 8
WIDTH, HEIGHT, MARGIN = 440, 240, (46, 14, 34, 40)  # px; margin: left, right, top, bottom
STYLE = (
    "body{font-family:system-ui,sans-serif;margin:1.5em;color:#222}h1{font-size:1.3em;margin:0 0 .4em}"
    "h2{font-size:1.05em;margin:1.2em 0 .4em}.now{font-size:1.15em;background:#eef4fb;padding:.6em .8em;"
    "border-radius:6px}.ended{background:#f3f3f3}.bad{color:#b00}.ok{color:#070}table{border-collapse:collapse}"
    "td,th{padding:.15em .7em;text-align:right}th{border-bottom:1px solid #999}"
    "svg{background:#fff;border:1px solid #ddd;margin-right:1em}.plots{display:flex;flex-wrap:wrap}"
)
ENDED = {
    Status.COMPLETED: "completed",
    Status.ABORTED: "aborted",
    Status.FAILED: "failed",
    Status.BUDGET_SPENT: "its budget is spent",
}
NOT_CONNECTED = {"connected": False, "polling": False, "last_seen_s_ago": None}


def number(value, digits: int = 4) -> str:
    """A number for a person: 4 significant digits, '-' for none or NaN, yes/no for a flag."""
    if value is None:
        return "-"
    if isinstance(value, (bool, np.bool_)):
        return "yes" if value else "no"
    if isinstance(value, (tuple, list)):
        return "(" + ", ".join(number(v, digits) for v in value) + ")" if len(value) > 1 else number(value[0], digits)
    value = float(value)
    return "-" if not math.isfinite(value) else f"{value:.{digits}g}"


def render(status: dict, state: EngineState | None) -> str:
    """The whole page for the campaign's committed ``state`` (None: not started) and the
    exchange's ``status()`` (only its "instrument_pc" is read)."""
    if state is None:
        body = ["<h1>noisebo campaign</h1><p class='now'>starting: the campaign has not begun yet</p>"]
        ended = False
    else:
        pc = status.get("instrument_pc") or NOT_CONNECTED
        name = status.get("instrument") or None  # the instrument this bridge serves, of several
        step = engine.ask(state, name)
        ended = isinstance(step, Done)
        serving = f", instrument {html.escape(name)}" if name else ""
        body = [
            f"<h1>noisebo campaign {html.escape(campaign_id(state))}{serving}</h1>",
            _now(step, state, pc),
            _progress(step, state, name),
            _connection(pc, ended),
            "<h2>What the campaign has learned</h2><div class='plots'>",
            _f_plot(state),
            _noise_plot(state),
            "</div>",
            _last_points(state),
        ]
    refresh = "" if ended else f"<meta http-equiv='refresh' content='{REFRESH_S}'>"
    return (
        f"<!doctype html><html><head><meta charset='utf-8'>{refresh}"
        f"<title>noisebo campaign</title><style>{STYLE}</style></head><body>{''.join(body)}</body></html>"
    )


def _now(step: Request | DecisionDue | Wait | Done, state: EngineState, pc: dict) -> str:
    """The campaign's phase: the shot it wants (measured, or waiting for an instrument PC that has
    not connected), the decision it is making, or its end and why."""
    n_steps = state.config.schedule.n_steps
    if isinstance(step, Request):
        kind = "seed point" if step.step < 0 else f"BO step {shown_step(step.step)} of {n_steps}"
        shot = (
            f"point {step.point} ({kind}) at x = {number(step.x)}, t = {number(step.t)} s: "
            f"shot {step.taken + 1} of {step.wanted}"
        )
        if not pc["connected"]:
            return f"<p class='now'>waiting for the instrument PC to connect, to measure {shot}</p>"
        return f"<p class='now'>measuring {shot}</p>"
    if isinstance(step, Wait):
        return f"<p class='now'>waiting for the other instruments: {html.escape(step.reason)}</p>"
    if isinstance(step, DecisionDue):
        own = next((f for f in state.flights if f.instrument and f.instrument == step.instrument), None)
        if step.take_over >= 0:
            what = f"taking over point {step.take_over}: {html.escape(step.reason)}"
        elif step.reduce and own is not None:
            what = f"reducing point {own.point}: its {len(own.taken)} shots are in"
        elif step.reduce:
            what = f"reducing point {len(state.points)}: its {len(state.taken)} shots are in"
        elif step.final:
            why = f" ({html.escape(step.budget)})" if step.budget else ""
            what = f"finishing: no more points to measure{why}; summarising the campaign"
        else:
            what = f"deciding BO step {shown_step(step.step)} of {n_steps}: where and how long to measure next"
        return f"<p class='now'>{what}</p>"
    said = ENDED.get(step.status, step.status.value)
    if step.reason and step.status is Status.BUDGET_SPENT:  # its reason says so: "budget spent: ..."
        said = html.escape(step.reason)
    elif step.reason:
        said += f" ({html.escape(step.reason)})"
    elif step.status is Status.COMPLETED:
        said += f", all {len(state.points)} points measured"
    return (
        f"<p class='now ended'>the campaign has ended: {said}</p>"
        "<p>This page no longer reloads itself: the bridge stops serving soon after the end.</p>"
    )


def _progress(step: Request | DecisionDue | Wait | Done, state: EngineState, name: str | None = None) -> str:
    """Finished work only: the committed points and their shots (the shots of a point not yet
    committed are counted apart), failed attempts, instrument time spent, budget, and the
    predicted optimal t once there is one."""
    sched = state.config.schedule
    done, total = len(state.points), sched.n_seed + sched.n_steps
    finished_shots = sum(len(entry.shots) for entry in state.points)
    failed = len(state.failures)
    budget = (
        ""
        if state.budget_s is None
        else f"; budget {number(state.budget_s)} s, {number(max(state.budget_s - state.spent_s, 0.0))} s left"
    )
    wall, wall_left = state.wall_budget_s, engine.wall_left(state)  # the budget a resume may have raised
    budget += f"; wall time {number(state.wall_s)} s" + (
        "" if wall is None or wall_left is None else f" of {number(wall)} s, {number(max(wall_left, 0.0))} s left"
    )
    own_budget, own_left = instrument_budget.budget(state, name or ""), instrument_budget.left(state, name or "")
    if own_budget is not None and own_left is not None:
        budget += (
            f"; {html.escape(name or '')}'s own budget {number(own_budget)} s, {number(max(own_left, 0.0))} s left"
        )
    own = name if state.config.noise_model.per_instrument and name else None
    learned = state.data if own is None else own_data(state, own)  # a law per instrument: this one's
    t_opt = f"{number(learned.t_opt_history[-1])} s" if learned.t_opt_history else "not yet (after the first decision)"
    converged = "yes" if learned.is_converged else "not yet"
    if own is not None:
        t_opt, converged = f"{t_opt} for {html.escape(own)}", f"{converged} (its own law)"
    more = ""
    if state.config.instruments is not None and state.flights:
        on = ", ".join(f"{f.point} on {html.escape(f.instrument)}" for f in state.flights)
        more = f" (and {len(state.taken)} shots of the points in flight: {on})"
    elif state.taken:
        doing = "being reduced" if isinstance(step, DecisionDue) and step.reduce else "being measured"
        more = f" (and {len(state.taken)} of point {done}, {doing})"
    return (
        f"<h2>Progress</h2><p><progress value='{done}' max='{max(total, 1)}'></progress> {done} of {total} points "
        f"finished, {finished_shots} shots{more}, {failed} failed attempt{'s' * (failed != 1)}; instrument time "
        f"spent {number(state.spent_s)} s{budget}</p><p>predicted optimal t: {t_opt}; noise model converged: "
        f"{converged}</p>"
    )


def _connection(pc: dict, ended: bool) -> str:
    """The instrument PC as the exchange knows it: never heard from, polling for the next shot, or
    last heard from some seconds ago (measuring a shot it took, or gone)."""
    if not pc["connected"]:
        return f"<p class='bad'>instrument PC: {'never connected' if ended else 'not connected yet'}</p>"
    seen = "" if pc["last_seen_s_ago"] is None else f"last seen {number(pc['last_seen_s_ago'], 3)} s ago"
    if ended:
        return f"<p>instrument PC: {seen or 'connected'}</p>"
    detail = ", waiting for the next shot" if pc["polling"] else (f", {seen}" if seen else "")
    return f"<p class='ok'>instrument PC: connected{detail}</p>"


def _last_points(state: EngineState) -> str:
    """The last points committed, newest first (with several instruments, each one's)."""
    several = state.config.instruments is not None
    rows = []
    for entry in state.points[::-1][:LAST_POINTS]:
        p = entry.committed.point
        measured = "" if p.noise_measured else " (model)"
        by = f"<td>{html.escape(entry.instrument)}</td>" if several else ""
        rows.append(
            f"<tr><td>{entry.committed.index}</td>{by}<td>{number(p.x)}</td><td>{number(p.t)}</td><td>{p.n_shots}</td>"
            f"<td>{number(p.value)}</td><td>{number(p.noise, 3)}{measured}</td></tr>"
        )
    if not rows:
        return "<h2>Last points</h2><p>none yet</p>"
    instrument = "<th>instrument</th>" if several else ""
    return (
        f"<h2>Last points</h2><table><tr><th>point</th>{instrument}<th>x</th><th>t (s)</th><th>shots</th>"
        f"<th>value</th><th>noise</th></tr>{''.join(rows)}</table>"
    )


def _f_plot(state: EngineState) -> str:
    pts = [e.committed.point for e in state.points]
    if state.config.space.dimensions != 1:
        return _message_plot("f", "a map of several axes: see the Rerun view")
    from noisebo.models.grids import grids

    series: list[tuple] = []
    if state.decisions:
        last = state.decisions[-1]
        x = grids(state.config).x
        x = x[:, 0] if x.ndim == 2 else x
        sd = np.sqrt(np.maximum(last.f_var, 0.0))
        series += [
            ("band", x, last.f_mean - 2 * sd, last.f_mean + 2 * sd, "#cfe0f3"),
            ("line", x, last.f_mean, None, "#1f5fa8"),
        ]
    if pts:
        series.append(("points", [p.x[0] for p in pts], [p.value for p in pts], None, "#d2540a"))
    space = state.config.space
    return plot(
        "f: the model (mean ± 2 sd) and the measured points", "x", "f", series, x_range=(space.x_min, space.x_max)
    )


def _noise_plot(state: EngineState) -> str:
    measured = [
        e.committed.point
        for e in state.points
        if e.committed.point.noise_measured and math.isfinite(e.committed.point.shot_std)
    ]
    series: list[tuple] = []
    if state.decisions:
        from noisebo.models.grids import grids

        last, t = state.decisions[-1], grids(state.config).t
        if last.noise_mean.ndim == 1 and len(last.noise_mean) == len(t):
            sd = np.sqrt(np.maximum(last.noise_var, 0.0))
            low = np.maximum(last.noise_mean - 2 * sd, 0.0)  # an sd is never negative
            series += [
                ("band", t, low, last.noise_mean + 2 * sd, "#d9ecd0"),
                ("line", t, last.noise_mean, None, "#2d7a1f"),
            ]
    if measured:
        series.append(("points", [p.t for p in measured], [p.shot_std for p in measured], None, "#d2540a"))
    space = state.config.space
    return plot(
        "single-shot noise: the model and the measured sd",
        "t (s)",
        "noise",
        series,
        log_x=True,
        x_range=(space.t_min, space.t_max),
        y_floor=0.0,
    )


def _message_plot(title: str, message: str) -> str:
    return (
        f"<svg width='{WIDTH}' height='{HEIGHT}' role='img'><text x='10' y='20'>{html.escape(title)}</text>"
        f"<text x='{WIDTH // 2}' y='{HEIGHT // 2}' text-anchor='middle' fill='#777'>{html.escape(message)}</text></svg>"
    )


def ticks(lo: float, hi: float, n: int = 5) -> list[float]:
    """About n round tick values within [lo, hi]."""
    if not hi > lo:
        return [lo]
    step = 10 ** math.floor(math.log10((hi - lo) / n))
    step *= next(m for m in (1, 2, 2.5, 5, 10) if (hi - lo) / (step * m) <= n)
    first = math.ceil(lo / step) * step
    return [first + k * step for k in range(int((hi - first) / step + 1e-9) + 1)]


def plot(
    title: str,
    xlabel: str,
    ylabel: str,
    series: Sequence[tuple],
    log_x: bool = False,
    x_range: tuple[float, float] | None = None,
    y_floor: float = -math.inf,
) -> str:
    """An SVG chart of ``series``: ("line" | "points", xs, ys, None, colour) or ("band", xs, lo, hi,
    colour); x on a log scale when ``log_x``, over ``x_range`` (the config's space) when given, else
    over the data; y never below ``y_floor`` (0 for a standard deviation)."""
    if not series:
        return _message_plot(title, "nothing measured yet")
    fx = (lambda v: np.log10(np.asarray(v, dtype=float))) if log_x else (lambda v: np.asarray(v, dtype=float))
    xs = np.concatenate([fx(s[1]) for s in series])
    ys = np.concatenate(
        [np.asarray(s[2], dtype=float) for s in series]
        + [np.asarray(s[3], dtype=float) for s in series if s[3] is not None]
    )
    xs, ys = xs[np.isfinite(xs)], ys[np.isfinite(ys)]
    if not len(xs) or not len(ys):
        return _message_plot(title, "nothing measured yet")
    x0, x1 = (float(xs.min()), float(xs.max())) if x_range is None else (float(fx(x_range[0])), float(fx(x_range[1])))
    y0, y1 = float(ys.min()), float(ys.max())
    x0, x1 = (x0 - 0.5, x1 + 0.5) if x1 == x0 else (x0, x1)
    pad = 0.05 * (y1 - y0) if y1 > y0 else 0.5
    y0, y1 = max(y0 - pad, y_floor), y1 + pad
    left, right, top, bottom = MARGIN
    px = lambda v: left + (v - x0) / (x1 - x0) * (WIDTH - left - right)  # noqa: E731
    py = lambda v: HEIGHT - bottom - (v - y0) / (y1 - y0) * (HEIGHT - top - bottom)  # noqa: E731
    parts = [
        f"<svg width='{WIDTH}' height='{HEIGHT}' role='img' font-size='11'>",
        f"<text x='{left}' y='14' font-size='12'>{html.escape(title)}</text>",
    ]
    for kind, sx, sy, hi, colour in series:
        sx, sy = fx(sx), np.asarray(sy, dtype=float)
        if kind == "band":
            upper = " ".join(f"{px(a):.1f},{py(b):.1f}" for a, b in zip(sx, np.asarray(hi, dtype=float)))
            lower = " ".join(f"{px(a):.1f},{py(b):.1f}" for a, b in zip(sx[::-1], sy[::-1]))
            parts.append(f"<polygon points='{upper} {lower}' fill='{colour}'/>")
        elif kind == "line":
            path = " ".join(f"{px(a):.1f},{py(b):.1f}" for a, b in zip(sx, sy) if math.isfinite(b))
            parts.append(f"<polyline points='{path}' fill='none' stroke='{colour}' stroke-width='1.6'/>")
        else:
            parts += [
                f"<circle cx='{px(a):.1f}' cy='{py(b):.1f}' r='2.6' fill='{colour}'/>"
                for a, b in zip(sx, sy)
                if math.isfinite(a) and math.isfinite(b)
            ]
    parts.append(
        f"<line x1='{left}' y1='{HEIGHT - bottom}' x2='{WIDTH - right}' y2='{HEIGHT - bottom}' stroke='#555'/>"
        f"<line x1='{left}' y1='{top}' x2='{left}' y2='{HEIGHT - bottom}' stroke='#555'/>"
    )
    for v in ticks(x0, x1):
        label = number(10**v, 2) if log_x else number(v, 3)
        parts.append(f"<text x='{px(v):.1f}' y='{HEIGHT - bottom + 14}' text-anchor='middle'>{label}</text>")
    for v in ticks(y0, y1):
        parts.append(f"<text x='{left - 4}' y='{py(v) + 4:.1f}' text-anchor='end'>{number(v, 3)}</text>")
    parts.append(
        f"<text x='{(left + WIDTH - right) / 2:.0f}' y='{HEIGHT - 6}' text-anchor='middle'>"
        f"{html.escape(xlabel)}</text><text x='12' y='{(top + HEIGHT - bottom) / 2:.0f}' "
        f"transform='rotate(-90 12 {(top + HEIGHT - bottom) / 2:.0f})' text-anchor='middle'>"
        f"{html.escape(ylabel)}</text></svg>"
    )
    return "".join(parts)
