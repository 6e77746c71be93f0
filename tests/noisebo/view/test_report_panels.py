"""The report's panel of the predicted optimal t: its y range spans at least +-25 % of the values'
middle (a wobble of a few per cent looks small), with a margin, never beyond the config's t range;
with a noise law per instrument, one line per instrument and a star where its law converged."""

import math

import pytest

from noisebo.view.report import t_range_shown
from tests.noisebo.campaign.test_own_noise import campaign  # noqa: F401, F811  (the fixture)


@pytest.mark.parametrize(
    ("values", "expected"),
    [
        ([2.40, 2.51], (2.455 * 0.75, 2.455 * 1.25)),  # a 4 % wobble: widened to +-25 % of 2.455 s
        ([1.0, 5.0], (1.0 - 0.2, 5.0 + 0.2)),  # already wide: the values and a 5 % margin
        ([0.2, 0.21], (0.2, 0.205 * 1.25)),  # widened, but not below t_min
        ([9.0, 9.5], (9.25 * 0.75, 10.0)),  # nor above t_max
        ([math.nan, 2.0], (1.5, 2.5)),  # a step without a value is left out
        ([math.nan], (0.2, 10.0)),  # nothing to show: the whole t range
    ],
)
def test_the_t_axis_is_wide_enough_and_inside_the_t_range(values, expected):
    assert t_range_shown(values, 0.2, 10.0) == pytest.approx(expected)


def test_with_a_law_per_instrument_the_panel_draws_each_instruments_optimal_t(campaign, tmp_path):  # noqa: F811
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from noisebo.campaign.own_noise import state_standings
    from noisebo.config import CampaignConfig
    from noisebo.storage.hdf5 import write_snapshot
    from noisebo.storage.record import read_record
    from noisebo.view.report import _t_opt

    config, _, final, _ = campaign
    path = tmp_path / "two.h5"
    write_snapshot(path, final)
    record = read_record(path)
    fig, ax = plt.subplots()
    _t_opt(ax, record, CampaignConfig.model_validate(record.config), None)
    drawn = {line.get_label(): (list(line.get_xdata()), list(line.get_ydata())) for line in ax.get_lines()}
    plt.close(fig)
    for standing in state_standings(final):
        name = standing.instrument
        mine = [k for k, who in enumerate(record.steps.instrument) if who == name]
        steps, t_opts = drawn[f"{name}'s optimal t"]
        assert steps == [int(record.steps.step[k]) for k in mine] and t_opts[-1] == standing.t_opt
        if standing.converged_step is not None:
            assert drawn[f"{name} converged (step {standing.converged_step})"][0] == [standing.converged_step]
