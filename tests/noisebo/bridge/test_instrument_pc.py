"""The instrument PC's flow: its token read from a file (one line for a bad one), and the readings
it hands in: a simulator's, keyed by (seed, point, shot) as in a campaign's own process."""

import pytest

from noisebo.bridge.serve_simulator import measure_with
from noisebo.bridge.client import ShotRequest
from noisebo.campaign.driver import take_shot
from noisebo.config import ConfigError
from noisebo.events import Request
from noisebo.bridge.instrument_pc import read_token
from noisebo.instruments import build
from noisebo.config.sections import InstrumentConfig


def test_the_token_is_the_files_first_line(tmp_path):
    path = tmp_path / "north.token"
    path.write_text("  s3cret-token  \n")
    assert read_token(str(path)) == "s3cret-token"


@pytest.mark.parametrize(
    "content, message",
    [
        (None, "cannot read the bridge token (No such file or directory)"),
        ("\n", "the bridge token file is empty"),
    ],
)
def test_a_token_file_that_cannot_serve_is_one_line(content, message, tmp_path):
    path = tmp_path / "absent.token"
    if content is not None:
        path.write_text(content)
    with pytest.raises(ConfigError) as info:
        read_token(str(path))
    assert str(info.value) == f"{path}: {message}"


def test_a_simulators_reading_is_the_campaigns_own_for_the_same_shot():
    forrester = build(InstrumentConfig(kind="forrester", settings={"a0": 0.1, "a1": 2.0}))
    request = ShotRequest("c", point=4, shot=2, step=1, x=[0.3], t=1.5, wanted=3, attempt=1, seed=7, reading="scalar")
    engine_request = Request(point=4, x=(0.3,), t=1.5, wanted=3, taken=2, step=0, model_noise=None)
    assert measure_with(forrester)(request) == take_shot(forrester, 7, engine_request).value
    assert measure_with(forrester)(request) != measure_with(forrester)(request._replace(shot=1))
