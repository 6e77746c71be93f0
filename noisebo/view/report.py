"""Static figures for papers and reports, from campaign files alone (matplotlib, no display).

``report(FILE.h5)``: FILE_report.png in the spirit of the paper's Figure 5 (the trajectory over
the last acquisition map, the predicted optimal t per step, f against the truth, the noise model
with its data) and, for PFM, FILE_sweep.png (the last sweep with its SHO fit).
``report(DIR)``: over a sweep's files, convergence_steps.png (Figure S1: distribution of the first
converged step per policy) and sweep_summary.md / .json (the benchmark table).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from noisebo.config import CampaignConfig, parse_config
from noisebo.instruments.registry import description
from noisebo.metrics import campaign_figures, summarise_campaigns, summary_table
from noisebo.models.reward import true_optimal_t
from noisebo.state import format_position
from noisebo.storage.hdf5 import CampaignFileError, read_shot_fits, read_spectra
from noisebo.storage.record import CampaignRecord, read_record
from noisebo.view.area import axis_labels, draw_image
from noisebo.view.recording import instrument_curves, last_sweep, true_optimal_map
from noisebo.view.style import step_colours

DPI = 130


def _warn(line: str) -> None:
    import sys

    print(f"noisebo: {line}", file=sys.stderr, flush=True)


def report(target: Path, out_dir: Path | None = None) -> list[Path]:
    """Write the figures of a campaign file or a sweep directory; returns the files written."""
    target = Path(target)
    if target.is_dir():
        files = sorted(target.glob("*.h5"))
        if not files:
            raise CampaignFileError(f"{target}: no campaign files (*.h5) in this directory")
        return sweep_report(files, Path(out_dir) if out_dir else target)
    return campaign_report(target, Path(out_dir) if out_dir else target.parent)


def _units(config: CampaignConfig) -> tuple[str, str]:
    """(x's label, the value's label), from the config's first axis and the driver's description."""
    axis, described = config.space.axes[0], description(config.instrument.kind)
    return described.axis_label(axis.name, axis.units), described.value_label


def campaign_report(path: Path, out_dir: Path) -> list[Path]:
    data = read_record(path)
    config = parse_config(data.config)
    truth, law = instrument_curves(config, warn=_warn, source=(path, data.driver))
    out_dir.mkdir(parents=True, exist_ok=True)
    steps = data.points.step  # 0: a seed point; BO steps from 1 (storage.steps)
    colours = step_colours(steps, config.schedule.n_steps)
    field = _t_map(data) is not None
    if config.space.dimensions == 1:
        fig = Figure(figsize=(12, 12.5 if field else 8.5), layout="constrained")
        axes = fig.subplots(3 if field else 2, 2)
        _trajectory(axes[0, 0], data, config, colours)
        _t_opt(axes[0, 1], data, config, law)
        _f(axes[1, 0], data, config, truth, colours)
        _noise(axes[1, 1], data, config, law, colours)
        if field:
            _field_lines(axes[2], data, config, true_optimal_map(config) if truth is not None else None)
    else:
        fig = Figure(figsize=(16, 9), layout="constrained")
        axes = fig.subplots(2, 3)
        _area_panels(axes[0], data, config, truth)
        _t_opt(axes[1, 0], data, config, law)
        _noise(axes[1, 1], data, config, law, colours)
        if field and config.space.dimensions == 2:
            _t_map_image(axes[1, 2], data, config)
        else:
            _points_by_value(axes[1, 2], data, config)
    several = sorted(set(data.points.instrument) - {""})
    on = f" on {len(several)} instruments ({', '.join(several)})" if several else ""
    fig.suptitle(
        f"{data.config['name']}: seed {data.seed}, {data.policy} policy, {len(data.points)} points{on} ({data.status})",
        fontsize=13,
    )
    written = [out_dir / f"{path.stem}_report.png"]
    fig.savefig(written[0], dpi=DPI)
    fits = read_shot_fits(path)
    if fits is not None and len(data.points):
        written.append(_sweep_figure(path, data, fits, out_dir))
    return written


def _final_f(data: CampaignRecord) -> tuple[np.ndarray, np.ndarray] | None:
    """The last model of f, (mean, variance) on the grid: the final one, else the last step's."""
    if data.summary is not None:
        return data.summary.f_mean, data.summary.f_var
    arrays = data.steps.arrays
    return (arrays["f_mean"][-1], arrays["f_var"][-1]) if len(data.steps) else None


def _area_panels(axes, data: CampaignRecord, config: CampaignConfig, truth) -> None:
    """Two axes: GP mean and sd over the area with the measured points coloured by their t, and
    the truth (or, without one, the last acquisition map's best over t). Beyond two axes, the
    reference points are not a grid: the panels show the first two axes' projection."""
    _, f_label = _units(config)
    p, final = data.points, _final_f(data)
    xy = np.asarray(p.x, dtype=np.float64).reshape(len(p), -1)
    if config.space.dimensions != 2 or final is None:
        for ax in axes:
            ax.set_axis_off()
        axes[0].text(
            0.5,
            0.5,
            "no model yet" if final is None else f"{config.space.dimensions} axes: see the projection below",
            ha="center",
            va="center",
        )
        return
    draw_image(
        axes[0], final[0], config, "f: GP mean, points coloured by t", f_label, points=xy, point_colours=np.log(p.t)
    )
    draw_image(
        axes[1],
        np.sqrt(np.maximum(final[1], 0.0)),
        config,
        "f: GP sd",
        f"sd ({f_label})",
        cmap="magma",
        points=xy,
        point_colours="w",
    )
    if truth is not None:
        draw_image(axes[2], truth, config, "truth (the simulator's)", f_label, points=xy, point_colours="w")
    elif len(data.steps):
        draw_image(
            axes[2],
            data.steps.arrays["acq_map"][-1],
            config,
            "last acquisition (best over t)",
            "1",
            cmap="Greys",
            points=xy,
            point_colours="tab:red",
        )


def _t_map(data: CampaignRecord) -> np.ndarray | None:
    """A noise field's t*(x) on the grid: the final model's, else the last decision's; None
    for an x-independent noise model."""
    summary = data.summary
    if summary is not None and summary.t_opt_map.size:
        return np.asarray(summary.t_opt_map, dtype=np.float64)
    maps = data.steps.arrays.get("t_opt_map")
    return np.asarray(maps[-1], dtype=np.float64) if maps is not None and len(maps) else None


def _field_lines(axes, data: CampaignRecord, config: CampaignConfig, truth) -> None:
    """One axis, a noise field: t*(x), and the single-shot noise at it, against the simulator's."""
    x_label, f_label = _units(config)
    x, p = data.grid["x"], data.points
    t_map = _t_map(data)
    axes[0].plot(x, t_map, color="tab:blue", label="predicted t*(x)")
    if truth is not None:
        axes[0].plot(x, truth[0], color="k", lw=1.2, ls="--", label="the simulator's t*(x)")
    axes[0].scatter(p.x, p.t, s=14, color="0.4", zorder=3, label="measured (x, t)")
    axes[0].set(xlabel=x_label, ylabel="optimal t (s)", title="optimal time per position (noise field)")
    axes[0].legend(fontsize=8)
    summary = data.summary
    if summary is not None and summary.noise_map.size:
        axes[1].plot(x, summary.noise_map, color="tab:red", label="predicted Noise(x, t*(x))")
    if truth is not None:
        axes[1].plot(x, truth[1], color="k", lw=1.2, ls="--", label="the simulator's, at its t*(x)")
    measured = p.noise_measured.astype(bool) & np.isfinite(p.shot_std)
    axes[1].scatter(
        p.x[measured],
        p.shot_std[measured],
        s=16,
        color="0.3",
        zorder=3,
        label="measured single-shot sd (at the point's t)",
    )
    axes[1].set(xlabel=x_label, ylabel=f"single-shot noise sd ({f_label})", title="noise per position", ylim=(0, None))
    axes[1].legend(fontsize=8)


def _t_map_image(ax, data: CampaignRecord, config: CampaignConfig) -> None:
    p = data.points
    xy = np.asarray(p.x, dtype=np.float64).reshape(len(p), -1)
    draw_image(
        ax,
        _t_map(data),
        config,
        "optimal t per position (noise field); points",
        "t*(x) (s)",
        cmap="cividis",
        points=xy,
        point_colours="w",
    )


def _points_by_value(ax, data: CampaignRecord, config: CampaignConfig) -> None:
    """The measured points over the first two axes, coloured by value, sized by t."""
    _, f_label = _units(config)
    p = data.points
    xy = np.asarray(p.x, dtype=np.float64).reshape(len(p), -1)
    t = np.asarray(p.t, dtype=np.float64)
    size = 10 + 60 * (t - config.space.t_min) / (config.space.t_max - config.space.t_min)
    dots = ax.scatter(xy[:, 0], xy[:, 1], c=p.value, s=size, cmap="viridis", edgecolor="k", linewidth=0.4)
    ax.figure.colorbar(dots, ax=ax, label=f_label, fraction=0.046, pad=0.02)
    labels = axis_labels(config)
    ax.set(
        xlabel=labels[0],
        ylabel=labels[1],
        xlim=(config.space.lows[0], config.space.highs[0]),
        ylim=(config.space.lows[1], config.space.highs[1]),
        title="measured values (marker size: t)",
    )


def _step_colourbar(fig_ax, n_steps: int) -> None:
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import Normalize
    from matplotlib.ticker import MaxNLocator

    sm = ScalarMappable(norm=Normalize(1, max(n_steps, 2)), cmap="viridis")
    bar = fig_ax.figure.colorbar(sm, ax=fig_ax, label="BO step (grey: seed points)", fraction=0.05)
    bar.locator = MaxNLocator(integer=True)
    bar.update_ticks()


INSTRUMENT_MARKERS = ("o", "s", "^", "D", "v", "P", "X", "*")


def _trajectory(ax, data: CampaignRecord, config: CampaignConfig, colours) -> None:
    s, p, steps = config.space, data.points, data.steps
    x_label, _ = _units(config)
    if len(steps):
        acq = np.asarray(steps.arrays["acq_map"][-1], dtype=np.float64).T
        shown = np.where(np.isfinite(acq), acq, np.nan)
        # the map as a background, its values relative (darker: more wanted): one colour bar, the steps'
        ax.imshow(
            shown, origin="lower", aspect="auto", cmap="Greys", extent=(s.x_min, s.x_max, s.t_min, s.t_max), alpha=0.6
        )
    names = sorted(set(p.instrument) - {""})
    if names:  # several instruments: one marker each, the colour still the step
        for name, marker in zip(names, INSTRUMENT_MARKERS * len(names)):
            mine = np.asarray(p.instrument) == name
            ax.scatter(
                p.x[mine],
                p.t[mine],
                c=np.asarray(colours)[mine],
                marker=marker,
                s=44,
                edgecolor="k",
                linewidth=0.5,
                zorder=3,
                label=f"measured by {name}",
            )
        ax.legend(fontsize=8, loc="upper right")
    else:
        ax.scatter(p.x, p.t, c=colours, s=36, edgecolor="k", linewidth=0.5, zorder=3)
    where = f"over the acquisition map of step {len(steps)} (darker: higher)" if len(steps) else "(no decision yet)"
    ax.set(
        xlabel=x_label,
        ylabel="exposure / sweep time t (s)",
        title=f"measured points {where}",
        xlim=(s.x_min, s.x_max),
        ylim=(s.t_min, s.t_max),
    )
    _step_colourbar(ax, config.schedule.n_steps)


def _t_opt(ax, data: CampaignRecord, config: CampaignConfig, law) -> None:
    steps, s, r = data.steps, config.space, config.reward
    k = steps.step
    per_instrument = config.noise_model.per_instrument and config.instruments is not None
    whose = ""
    if per_instrument:
        _t_opt_by_instrument(ax, steps, config.instrument_names)
        whose = f" of {config.instrument_names[0]}"  # the truth drawn is the first instrument's
    else:
        ax.plot(k, steps.t_opt, "o-", color="tab:blue", label="predicted optimal t")
    if law is not None:
        t_star = true_optimal_t(law, s.t_min, s.t_max, r.alpha, r.beta)
        ax.axhline(t_star, color="k", ls="--", lw=1, label=f"true t*{whose} = {t_star:.3g} s")
    converged = data.converged_step
    if converged is not None and not config.noise_model.per_instrument:
        ax.axvline(converged, color="tab:green", ls=":", label=f"noise model converged (step {converged})")
    if data.summary is not None:
        ax.plot([k[-1] + 1 if len(k) else 1], [data.summary.t_opt], "s", color="tab:red", label="final model")
    shown = [*steps.t_opt, *([data.summary.t_opt] if data.summary is not None else [])]
    if law is not None:
        shown.append(t_star)
    ax.set(
        xlabel="BO step",
        ylabel="predicted optimal t (s)",
        title="evolution of the predicted optimal t",
        ylim=t_range_shown(shown, s.t_min, s.t_max),
    )
    ax.legend(fontsize=8)


def _t_opt_by_instrument(ax, steps, names) -> None:
    """A law per instrument: each instrument's predicted optimal t at the steps decided for it,
    with a star where its own law converged."""
    k = np.asarray(steps.step)
    for colour, name in enumerate(names):
        mine = np.asarray([who == name for who in steps.instrument], dtype=bool)
        if not mine.any():
            continue
        line = ax.plot(
            k[mine], np.asarray(steps.t_opt)[mine], "o-", color=f"C{colour}", ms=3, label=f"{name}'s optimal t"
        )
        first = next((i for i in np.flatnonzero(mine) if steps.converged[i]), None)
        if first is not None:
            ax.plot(
                k[first],
                steps.t_opt[first],
                "*",
                color=line[0].get_color(),
                ms=12,
                label=f"{name} converged (step {k[first]})",
            )


T_SPAN_SHOWN = 0.25  # the predicted optimal t's axis spans at least +-25 % of its middle value


def t_range_shown(values, t_min: float, t_max: float, span: float = T_SPAN_SHOWN) -> tuple[float, float]:
    """The y range (s) of the predicted optimal t: the values with a margin, widened to at least
    +-``span`` of their middle, so that a wobble of a few per cent looks as small as it is;
    never beyond [t_min, t_max]."""
    finite = [float(v) for v in values if np.isfinite(v)]
    if not finite:
        return t_min, t_max
    low, high = min(finite), max(finite)
    middle = (low + high) / 2
    margin = 0.05 * (high - low)
    return max(t_min, min(low - margin, middle * (1 - span))), min(t_max, max(high + margin, middle * (1 + span)))


def _f(ax, data: CampaignRecord, config: CampaignConfig, truth, colours) -> None:
    x_label, f_label = _units(config)
    x, p = data.grid["x"], data.points
    final = _final_f(data)
    if truth is not None:
        ax.plot(x, truth, color="k", lw=1.2, label="truth")
    if final is not None:
        mean, sd = final[0], np.sqrt(np.maximum(final[1], 0.0))
        ax.plot(x, mean, color="tab:blue", label="GP mean")
        ax.fill_between(x, mean - 2 * sd, mean + 2 * sd, color="tab:blue", alpha=0.2, label="+-2 sd")
    err = p.noise / np.sqrt(np.maximum(p.n_shots, 1))
    ax.errorbar(p.x, p.value, yerr=err, fmt="none", ecolor="0.4", elinewidth=0.8, zorder=2)
    ax.scatter(p.x, p.value, c=colours, s=30, edgecolor="k", linewidth=0.5, zorder=3, label="measured (mean +- se)")
    ax.set(xlabel=x_label, ylabel=f_label, title="f: final prediction against the truth")
    ax.legend(fontsize=8)


def _noise(ax, data: CampaignRecord, config: CampaignConfig, law, colours) -> None:
    _, f_label = _units(config)
    p, grid, steps = data.points, data.grid, data.steps
    if law is not None:
        t = grid["t_fine"]
        ax.plot(t, law(t), color="k", lw=1.2, label="true noise law")
    if len(steps):
        mean, sd = steps.arrays["noise_mean"][-1], np.sqrt(np.maximum(steps.arrays["noise_var"][-1], 0.0))
        ax.plot(grid["t"], mean, color="tab:red", label=f"noise model (step {len(steps)})")
        ax.fill_between(grid["t"], mean - 2 * sd, mean + 2 * sd, color="tab:red", alpha=0.2, label="+-2 sd")
    measured = p.noise_measured.astype(bool) & np.isfinite(p.shot_std)
    ax.scatter(
        p.t[measured],
        p.shot_std[measured],
        c=colours[measured],
        s=30,
        edgecolor="k",
        linewidth=0.5,
        zorder=3,
        label="measured single-shot sd",
    )
    few = ~p.noise_measured.astype(bool) & np.isfinite(p.shot_std)
    if few.any():
        ax.scatter(
            p.t[few], p.shot_std[few], facecolor="none", edgecolor="0.5", s=22, zorder=2, label="sd of few-shot points"
        )
    ax.set(
        xlabel="exposure / sweep time t (s)",
        ylabel=f"single-shot noise sd ({f_label})",
        title="noise model with its data",
        ylim=(0, None),
    )
    ax.legend(fontsize=8)


def _sweep_figure(path: Path, data: CampaignRecord, fits: dict, out_dir: Path) -> Path:
    from noisebo.sho import sho_amplitude

    last = int(data.points.index[-1])  # the last point committed
    spectrum, fit = last_sweep(lambda point: read_spectra(path, point), data.shots.point, fits, last)
    freq, amp = spectrum[0].astype(np.float64), spectrum[1].astype(np.float64)
    fig = Figure(figsize=(7, 4.2), layout="constrained")
    ax = fig.subplots()
    ax.plot(freq / 1e3, amp / 1e3, ".", ms=1.5, color="0.5", label=f"sweep ({freq.size} samples)")
    if fit is not None and np.isfinite(fit["amplitude"]):
        ax.plot(
            freq / 1e3,
            sho_amplitude(freq, fit["amplitude"], fit["resonance_hz"], fit["q"]) / 1e3,
            color="tab:red",
            label=f"SHO fit: r = {fit['amplitude']:.3g} +- {fit['amplitude_se']:.2g} pm, "
            f"f0 = {fit['resonance_hz'] / 1e3:.2f} kHz, Q = {fit['q']:.0f}",
        )
    t = float(data.points.t[last])
    ax.set(
        xlabel="drive frequency (kHz)",
        ylabel="amplitude (nm)",
        title=f"last sweep of point {last} (x = {format_position(data.points.x[last], 3)} um, t = {t:.3g} s)",
    )
    ax.legend(fontsize=8)
    out = out_dir / f"{path.stem}_sweep.png"
    fig.savefig(out, dpi=DPI)
    return out


def benchmark_table(rows: dict[str, dict]) -> str:
    """``noisebo.metrics.summary_table`` of records (``figures_from_file``; BO steps from 1)."""
    return summary_table(rows)


def _first_converged(steps) -> int | None:
    """The first BO step (counted from 1) whose ``converged`` flag is set, or None."""
    hits = np.flatnonzero(steps.converged.astype(bool))
    return int(steps.step[hits[0]]) if hits.size else None


def figures_from_file(path: str | Path) -> dict:
    """Benchmark figures of one finished campaign, from its HDF5 file alone."""
    from noisebo.instruments import build

    data = read_record(Path(path))
    config = parse_config(data.config)
    if data.summary is None:
        raise CampaignFileError(f"{path}: campaign not finished (status {data.status})")
    record = campaign_figures(
        config,
        build(config.instrument),
        data.steps.t_opt,
        data.summary.t_opt,
        data.grid["x"],
        data.summary.f_mean,
        data.shots.t,
        data.steps.latency_s,
        _first_converged(data.steps),
    )
    record.update(seed=data.seed, file=str(path))
    return record


def write_summary(paths: list, out_dir: str | Path) -> tuple[Path, Path]:
    """sweep_summary.md (a table per policy), sweep_summary.json (one record per campaign) and
    convergence_steps.png (Figure S1) of finished campaign files; returns (table, figure)."""
    records = [figures_from_file(p) for p in paths]
    policies = sorted({r["policy"] for r in records})
    rows = {p: summarise_campaigns([r for r in records if r["policy"] == p]) for p in policies}
    out = Path(out_dir)
    (out / "sweep_summary.json").write_text(json.dumps({"records": records, "summary": rows}, indent=1))
    table, figure = out / "sweep_summary.md", out / "convergence_steps.png"
    table.write_text("Median [IQR] over campaigns.\n\n" + benchmark_table(rows) + "\n")
    convergence_figure(records, figure)
    return table, figure


def sweep_report(files: list[Path], out_dir: Path) -> list[Path]:
    """Figure S1 (first converged step per policy) and the summary table of finished campaigns;
    unfinished files are left out and named."""
    finished: list[Path] = []
    skipped: list[Path] = []
    for f in files:
        (finished if read_record(f).summary is not None else skipped).append(f)
    if not finished:
        raise CampaignFileError(f"none of the {len(files)} campaign files has finished")
    out_dir.mkdir(parents=True, exist_ok=True)
    table, figure = write_summary(finished, out_dir)
    if skipped:
        print(f"left out {len(skipped)} unfinished campaign(s): " + ", ".join(p.name for p in skipped))
    return [figure, table]


def convergence_figure(records: list[dict], out: Path) -> None:
    from matplotlib.ticker import MaxNLocator

    policies = sorted({r["policy"] for r in records})
    n_steps = max(len(r["t_opt_pred"]) for r in records)
    bins = np.arange(1, n_steps + 2)  # first converged step, 1-based; n_steps + 1 = never
    fig = Figure(figsize=(8, 4.2), layout="constrained")
    ax = fig.subplots()
    width = 0.8 / len(policies)
    for i, policy in enumerate(policies):
        steps = [r["converged_step"] for r in records if r["policy"] == policy]
        k = np.asarray([n_steps + 1 if s is None else s for s in steps])
        counts = np.asarray([np.sum(k == b) for b in bins])
        ax.bar(
            bins + (i - (len(policies) - 1) / 2) * width,
            counts,
            width=width,
            label=f"{policy} ({len(steps)} campaigns, median {np.median(k):.0f})",
        )
    ax.set_xticks(bins, [str(b) for b in bins[:-1]] + ["never"])
    ax.set(
        xlabel="first BO step at which the noise model counts as converged",
        ylabel="campaigns",
        title="convergence of the noise model across seeds",
    )
    locator = ax.yaxis.get_major_locator()
    if isinstance(locator, MaxNLocator):  # the default AutoLocator is one
        locator.set_params(integer=True)
    ax.legend(fontsize=9)
    fig.savefig(out, dpi=DPI)
