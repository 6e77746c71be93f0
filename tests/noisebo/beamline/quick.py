"""The short Forrester campaign the bluesky tests run, and the check that a campaign file holds
the campaign ``noisebo run`` takes with the same seed."""

from pathlib import Path

import numpy as np
import yaml

from noisebo.campaign.driver import run_campaign
from noisebo.config import load_config
from noisebo.instruments import build
from noisebo.storage.record import read_record

ROOT = Path(__file__).resolve().parents[3]
FORRESTER = ROOT / "data" / "configs" / "forrester.yaml"

# Milliseconds of exposure, so the IOC's shots take as long as they say and the tests stay short.
QUICK = load_config(FORRESTER).with_overrides(
    space={"t_min": 0.002, "t_max": 0.05}, schedule={"n_steps": 3, "shots_before": 8}
)


def same_as_alone(path: Path, config=QUICK):
    """The campaign file at ``path``, completed with the points ``noisebo run`` takes."""
    alone = run_campaign(config, build(config.instrument), seed=0).state
    record = read_record(path)
    assert record.status == "completed"
    np.testing.assert_array_equal(record.points.x, alone.positions(1)[:, 0])
    np.testing.assert_array_equal(record.points.t, alone.column("t"))
    np.testing.assert_array_equal(record.points.value, alone.column("value"))
    return record


PFM = ROOT / "data" / "configs" / "pfm.yaml"
# The PFM line with sweeps of 20-100 ms (200-1000 samples), two BO steps.
QUICK_PFM = load_config(PFM).with_overrides(
    space={"t_min": 0.02, "t_max": 0.1}, schedule={"n_steps": 2, "shots_before": 6}
)


def written(config, folder: Path) -> Path:
    """``config`` as a YAML file in ``folder``, for an IOC that serves it (its longest sweep is
    this config's t_max)."""
    path = folder / f"{config.name}.yaml"
    path.write_text(yaml.safe_dump(config.model_dump(mode="json")))
    return path
