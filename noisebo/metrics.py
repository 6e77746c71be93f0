"""Campaign quality figures, as plain functions of arrays."""

from __future__ import annotations

import numpy as np


def rmse(predicted: np.ndarray, truth: np.ndarray) -> float:
    """Root-mean-square difference of two equal-shape arrays."""
    predicted, truth = np.asarray(predicted, dtype=np.float64), np.asarray(truth, dtype=np.float64)
    if predicted.shape != truth.shape:
        raise ValueError(f"shape mismatch: {predicted.shape} vs {truth.shape}")
    return float(np.sqrt(np.mean((predicted - truth) ** 2)))


def relative_error(estimate: float, truth: float) -> float:
    """|estimate - truth| / |truth|."""
    return abs(estimate - truth) / abs(truth)


def median_iqr(values) -> tuple[float, float, float]:
    """(median, 25th percentile, 75th percentile) of the finite values; NaNs if there are none."""
    arr = np.asarray([v for v in values if v is not None and np.isfinite(v)], dtype=np.float64)
    if arr.size == 0:
        return float("nan"), float("nan"), float("nan")
    q25, q50, q75 = np.percentile(arr, [25, 50, 75])
    return float(q50), float(q25), float(q75)


RMSE_POINTS = 200


def campaign_figures(
    config,
    instrument,
    t_opt_history,
    t_opt_final: float,
    grid_x: np.ndarray,
    f_mean_final: np.ndarray,
    shot_t: np.ndarray,
    latencies_s,
    converged_step: int | None,
) -> dict:
    """The benchmark figures of one finished campaign.

    t* comes from the instrument's true noise law and the configured reward; RMSE compares the
    final f prediction (interpolated from the x grid) with the truth at 200 evenly spaced x (for d > 1 axes, at the reference points). Either
    is None when the instrument does not know its truth. ``converged_step``: the first BO step
    (counted from 1) at which the campaign's own convergence rule held (None if it never did)."""
    from noisebo.models.reward import true_optimal_t

    s, rew = config.space, config.reward
    t_star = None
    from noisebo.campaign.driver import simulates

    simulator = simulates(instrument)
    if simulator:
        t_star = true_optimal_t(instrument.noise_law, s.t_min, s.t_max, rew.alpha, rew.beta)
    grid_x = np.asarray(grid_x, dtype=np.float64)
    if s.dimensions == 1:
        x_eval = np.linspace(s.x_min, s.x_max, RMSE_POINTS)
        truth = instrument.truth(x_eval[:, None]) if simulator else None
        predicted = None if truth is None else np.interp(x_eval, grid_x, f_mean_final)
    else:  # the reference points themselves: a grid over the area (two axes) or a Halton set
        truth = instrument.truth(grid_x) if simulator else None
        predicted = np.asarray(f_mean_final, dtype=np.float64)
    history = [float(v) for v in t_opt_history]
    return {
        "policy": config.acquisition.policy,
        "converged_step": converged_step,
        "t_opt_pred": history + [float(t_opt_final)],
        "t_star": t_star,
        "t_opt_rel_error": None if t_star is None else relative_error(t_opt_final, t_star),
        "rmse_f": None if truth is None or predicted is None else rmse(predicted, truth),
        "total_measurement_time": float(np.sum(shot_t)),
        "step_latency_s": [float(v) for v in latencies_s],
    }


def summarise_campaigns(records: list[dict]) -> dict:
    """Medians and IQRs over campaigns of one policy (records from ``campaign_figures``)."""
    conv = [r["converged_step"] for r in records]
    first = [r["step_latency_s"][0] for r in records if r["step_latency_s"]]
    rest = [v for r in records for v in r["step_latency_s"][1:]]
    return {
        "campaigns": len(records),
        "converged_within_10": sum(1 for c in conv if c is not None and c <= 10) / max(len(records), 1),
        "converged_step": median_iqr([c for c in conv if c is not None]),
        "t_rel_error": median_iqr([r["t_opt_rel_error"] for r in records]),
        "rmse_f": median_iqr([r["rmse_f"] for r in records]),
        "measurement_time_s": median_iqr([r["total_measurement_time"] for r in records]),
        "latency_first_s": median_iqr(first)[0],
        "latency_rest_s": median_iqr(rest)[0],
    }


def _fmt(m, digits: int = 3) -> str:
    return f"{m[0]:.{digits}f} [{m[1]:.{digits}f}, {m[2]:.{digits}f}]"


def summary_table(rows: dict[str, dict]) -> str:
    """A Markdown table of ``summarise_campaigns`` results keyed by policy (median [IQR])."""
    header = (
        "| policy | campaigns | converged by step 10 | first converged step | final abs(t_opt - t*)/t* "
        "| final RMSE f | measurement time (s) | latency step 1 (s) | latency median rest (s) |"
    )
    lines = [header, "|---" * (header.count("|") - 1) + "|"]
    for policy, s in rows.items():
        lines.append(
            f"| {policy} | {s['campaigns']} | {100 * s['converged_within_10']:.0f} % | {_fmt(s['converged_step'], 1)} "
            f"| {_fmt(s['t_rel_error'])} | {_fmt(s['rmse_f'])} | {_fmt(s['measurement_time_s'], 0)} "
            f"| {s['latency_first_s']:.2f} | {s['latency_rest_s']:.3f} |"
        )
    return "\n".join(lines)
