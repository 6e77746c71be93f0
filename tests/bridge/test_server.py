import json

import h5py
import pytest

from tests.bridge.conftest import call, post_value, remote_config, served

SMALL = {"space": {"n_x": 40, "n_t": 30}, "schedule": {"n_seed": 2, "n_steps": 0, "shots_before": 2}}


@pytest.fixture
def campaign(tmp_path):
    """A scalar campaign behind a bridge with a 1 KiB body limit, its first point measured."""
    config = remote_config("data/configs/forrester.yaml", SMALL, max_body_mib=1 / 1024)
    with served(config, tmp_path / "c.h5") as running:
        for shot in range(2):
            assert call(running.url, "GET", "/next?wait=5")[1]["shot"] == shot
            code, answer = post_value(running.url, 0, shot, 1.0 + shot)
            assert (code, answer["recorded"], answer["duplicate"], answer["shot"]) == (200, True, False, shot)
        yield running


VALUE = json.dumps({"value": 1.0}).encode()


@pytest.mark.parametrize("path, body, token, status, message", [
    ("/shots/1/0", VALUE, None, 401, "missing token"),
    ("/shots/1/0", VALUE, "wrong", 403, "wrong token"),
    ("/shots/0/1", json.dumps({"value": 2.0}).encode(), "ok", 200, None),  # the same reading again: a duplicate
    ("/shots/0/1", json.dumps({"value": 7.0}).encode(), "ok", 409, "already recorded with a different reading"),
    ("/shots/1/0", b'{"value": NaN}', "ok", 422, "not a finite number"),
    ("/shots/1/0", json.dumps({"spectrum": [[1.0] * 9] * 3}).encode(), "ok", 422, "one number per shot"),
    ("/shots/1/0", json.dumps({"value": 1.0, "pad": "x" * 2000}).encode(), "ok", 413, "over the bridge's limit of 1024 bytes"),
    ("/shots/1/5", VALUE, "ok", 409, "point 1 shot 5 is not wanted; the shot wanted now is point 1 shot 0"),
    ("/shots/9/0", VALUE, "ok", 409, "point 9 shot 0 is not wanted"),
    ("/shots/0/2", VALUE, "ok", 409, "point 0 shot 2 is finished"),
    ("/shots/1/0", b'{"value": 1.0', "ok", 400, "the body is not JSON"),
    ("/shots/1/0", b'{"reading": 1.0}', "ok", 422, "body.reading"),
    ("/shots/x/0", VALUE, "ok", 422, "path.point"),
    ("/shots/-1/0", VALUE, "ok", 422, "path.point"),
])
def test_bad_input_is_refused_with_the_problem_named_and_nothing_recorded(campaign, path, body, token, status, message):
    from tests.bridge.conftest import TOKEN

    before = campaign.journal_bytes()
    code, answer = call(campaign.url, "POST", path, body, token=TOKEN if token == "ok" else token)
    assert code == status
    if message is None:
        assert answer["duplicate"] is True
    else:
        assert message in answer["error"]
    assert campaign.journal_bytes() == before
    assert call(campaign.url, "GET", "/next?wait=5")[1]["point"] == 1  # still waiting for the same shot


def test_every_call_needs_the_token_and_the_status_shows_progress(campaign):
    from tests.bridge.conftest import TOKEN

    assert call(campaign.url, "GET", "/status", token=None)[0] == 401
    assert call(campaign.url, "GET", "/next", token="nope")[0] == 403
    status, progress = call(campaign.url, "GET", "/status")
    assert status == 200
    assert (progress["status"], progress["points"], progress["points_total"], progress["shots"]) == ("running", 1, 2, 2)
    assert progress["current"]["point"] == 1 and progress["instrument_pc"]["connected"] is True
    status, page = call(campaign.url, "GET", f"/?token={TOKEN}", token=None)
    assert status == 200 and "1/2 points" in page
    status, schema = call(campaign.url, "GET", "/openapi.json", token=None)
    assert {"/next", "/shots/{point}/{shot}", "/status"} <= set(schema["paths"])
    assert call(campaign.url, "GET", "/docs", token=None)[0] == 200
    assert call(campaign.url, "GET", "/nowhere")[1] == {"error": "Not Found"}


def test_the_campaign_completes_and_its_file_holds_each_reading_once(campaign):
    for shot in range(2):
        assert post_value(campaign.url, 1, shot, 3.0 + shot)[0] == 200
    assert post_value(campaign.url, 1, 1, 4.0)[1]["duplicate"] is True
    final = campaign.final()
    assert final.status.value == "completed"
    assert [s.reading.value for p in final.points for s in p.shots] == [1.0, 2.0, 3.0, 4.0]
    assert call(campaign.url, "GET", "/next?wait=1")[1]["kind"] == "done"
    with h5py.File(campaign.path) as f:
        assert f.attrs["status"] == "completed"


@pytest.mark.parametrize("spectrum, message", [
    ([[1.0] * 50] * 4, "4 rows × 50 samples; expected 2 or 3 rows"),
    ([1.0] * 50, "body.spectrum.rows.0"),
    ([[1.0] * 50, [1.0] * 50, [1.0] * 49], "rows of different lengths [49, 50]"),
    ([[1.0] * 3] * 3, "3 samples per row; expected 8 to"),
])
def test_a_spectrum_of_the_wrong_shape_is_refused(tmp_path, spectrum, message):
    config = remote_config("data/configs/pfm.yaml", SMALL)
    with served(config, tmp_path / "pfm.h5") as running:
        before = running.journal_bytes()
        code, answer = call(running.url, "POST", "/shots/0/0", json.dumps({"spectrum": spectrum}).encode())
        assert (code, message in answer["error"]) == (422, True), answer
        assert running.journal_bytes() == before


def test_an_instrument_pc_that_goes_silent_fails_its_shots_until_the_budget_stops_the_campaign(tmp_path):
    overrides = {**SMALL, "schedule": {**SMALL["schedule"], "min_failed": 3}}
    config = remote_config("data/configs/forrester.yaml", overrides, silence_s=0.3)
    with served(config, tmp_path / "c.h5") as running:
        assert call(running.url, "GET", "/next?wait=0")[1]["kind"] == "shot"  # it takes the first shot, then nothing
        final = running.final(timeout=60)
    assert final.status.value == "failed" and "3 of 3" in final.reason
    assert [f.kind for f in final.failures] == ["timeout"] * 3
    assert "nothing heard from it for 0.3 s" in final.failures[0].reason
