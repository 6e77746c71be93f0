"""The viewer layout of a campaign recording: maps and curves on top, traces and the log below."""

from __future__ import annotations

from noisebo.config import CampaignConfig
from noisebo.instruments.registry import description


def blueprint(config: CampaignConfig):
    """The ``rerun.blueprint.Blueprint``: acquisition map with the measured points (and those in
    flight, with several instruments), f with its
    band and the truth (for two axes: images of the GP mean and sd, the truth and the
    acquisition over the area; for more, the table of points), the noise model with its data, the normalised reward with t_opt (and the
    latest sweep where the driver's shots are spectra); below them the scalar traces and the decision log."""
    import rerun.blueprint as rrb

    coloured = "points by instrument, pale: in flight" if config.instruments is not None else "points by step"
    top: list[rrb.View] = [
        rrb.Spatial2DView(origin="acquisition", name=f"acquisition over (x, t); {coloured}"),
        rrb.Spatial2DView(origin="f", name="f(x): mean, +-2 sd band, truth, points"),
    ]
    if config.space.dimensions == 2:
        top = [
            rrb.Spatial2DView(origin="area/f_mean", name="f: GP mean over the area; points by t"),
            rrb.Spatial2DView(origin="area/f_sd", name="f: GP sd"),
            rrb.Spatial2DView(origin="area/truth", name="truth (simulator)"),
            rrb.Spatial2DView(origin="area/acquisition", name="acquisition, best over t"),
        ]
    elif config.space.dimensions > 2:
        top = [rrb.DataframeView(origin="campaign", name="measured points (x has more than two axes)")]
    middle = [
        rrb.Spatial2DView(origin="noise", name="Noise(t): model, +-2 sd band, law, measured"),
        rrb.Spatial2DView(origin="reward", name="normalised reward and predicted optimal t"),
    ]
    if description(config.instrument.kind).spectra:
        middle.append(rrb.Spatial2DView(origin="spectrum", name="latest sweep and its SHO fit"))
    traces = rrb.Vertical(
        rrb.TimeSeriesView(origin="traces/t_opt_s", name="predicted optimal t (s)"),
        rrb.TimeSeriesView(contents=["traces/a0", "traces/a1"], name="noise model A0, A1"),
        rrb.TimeSeriesView(
            contents=["traces/latency_s", "traces/measurement_time_s"],
            name="decision latency, cumulative measurement time (s)",
        ),
    )
    return rrb.Blueprint(
        rrb.Vertical(
            rrb.Horizontal(*top),
            rrb.Horizontal(*middle),
            rrb.Horizontal(traces, rrb.TextLogView(origin="log", name="decisions")),
            row_shares=[3, 2, 2],
        ),
        collapse_panels=True,
    )
