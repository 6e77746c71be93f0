import numpy as np
import pytest

from noisebo.instruments import Instrument, build
from noisebo.instruments.pfm import PFMInstrument, PFMSettings
from noisebo.instruments.pfm_profile import (
    ProfileError,
    ScanProfileConfig,
    SyntheticProfileConfig,
    scan_profile,
    synthetic_profile,
)
from noisebo.instruments.registry import validated
from noisebo.config import ConfigError, InstrumentConfig, ReductionConfig, parse_config
from noisebo.reduction import shot_value

SYNTH = PFMSettings(profile=SyntheticProfileConfig(length_um=1.0, n_domains=2, amplitude_pm=100.0, seed=0))
TUNED = ReductionConfig(sho={"nominal_resonance_hz": 372_000.0, "nominal_q": 250.0})


def test_scan_profile_is_the_signed_amplitude_along_the_line():
    profile = scan_profile(ScanProfileConfig())
    # 225 pixels; the scan's x axis runs 0..1 um over 256 pixels
    assert profile.length_um == pytest.approx(np.hypot(180, 135) / 255, rel=1e-6)
    assert profile.response_pm.min() < -50 and profile.response_pm.max() > 100  # both domain signs


def test_synthetic_profile_alternates_sign_and_vanishes_at_walls():
    profile = synthetic_profile(SyntheticProfileConfig(length_um=1.0, n_domains=2, wall_um=0.02))
    assert profile(0.25) > 50 and profile(0.75) < -50 and abs(profile(0.5)) < 1e-9


def test_driver_fits_the_protocol_and_is_deterministic():
    inst = build(InstrumentConfig(kind="pfm", settings=SYNTH.model_dump(mode="json")))
    assert isinstance(inst, Instrument) and inst.name == "pfm"
    a = inst.simulate(np.array([0.25]), 0.3, np.random.default_rng(5))
    b = inst.simulate(np.array([0.25]), 0.3, np.random.default_rng(5))
    assert a.value is None and a.spectrum.shape == (3, 3000) and a.spectrum.dtype == np.float32
    assert a.reduction == "sho"
    np.testing.assert_array_equal(a.spectrum, b.spectrum)


def test_fitted_sweep_measures_the_local_response():
    inst = PFMInstrument(SYNTH)
    rng = np.random.default_rng(0)
    for x in (0.25, 0.75):
        values = [shot_value(inst.simulate(np.array([x]), 1.0, rng), TUNED).value for _ in range(20)]
        assert np.mean(values) == pytest.approx(
            inst.truth(np.array([[x]]))[0], abs=3 * inst.noise_law(np.array([1.0]))[0]
        )


def test_noise_law_falls_with_sweep_time_towards_the_time_independent_floor():
    inst = PFMInstrument(SYNTH)
    t = np.array([0.1, 0.5, 2.0, 100.0])
    law = inst.noise_law(t)
    floor = inst._jitter_variance()
    assert np.all(np.diff(law) < 0) and floor >= SYNTH.background_pm**2
    # above the floor, the fit's variance falls as 1/t (10 000 t samples): A1^2/t + A0^2
    np.testing.assert_allclose((law**2 - floor) * t, (law[2] ** 2 - floor) * 2.0, rtol=0.02)


def test_time_independent_noise_by_hand_and_at_the_walls():
    # Without landing error: sd = sqrt(g^2 r(x)^2 + b^2) exactly (the quadrature of a constant).
    still = PFMInstrument(
        SYNTH.model_copy(update={"position_jitter_um": 0.0, "gain_jitter": 0.01, "background_pm": 0.5})
    )
    x = np.array([0.1, 0.25, 0.5])
    np.testing.assert_allclose(still.static_sd(x), np.sqrt((0.01 * still.truth(x[:, None])) ** 2 + 0.25), rtol=1e-9)
    # With it, a domain wall (x = 0.5) is noisier than a domain's middle.
    shaky = PFMInstrument(SYNTH.model_copy(update={"position_jitter_um": 0.005}))
    middle, wall = shaky.static_sd(np.array([0.25, 0.5]))
    assert wall > 2 * middle


@pytest.mark.parametrize(
    "change, message",
    [
        ({"profile": {"source": "scan", "file": "nowhere.h5"}}, "cannot open the PFM scan"),
        ({"profile": {"source": "scan", "start_px": [0, 0], "end_px": [300, 10]}}, "outside the 256 x 256 scan"),
    ],
)
def test_bad_profiles_name_the_problem(change, message):
    with pytest.raises(ProfileError, match=message):
        PFMInstrument(PFMSettings(**change))


@pytest.mark.parametrize(
    "instrument, field",
    [
        ({"q": 0.5}, "instrument.settings.q"),
        ({"sweep_half_span_hz": 400000.0}, "sweep_half_span_hz must be below"),
        ({"profile": {"source": "scan", "start_px": [3, 3], "end_px": [3, 3]}}, "must differ"),
        ({"profile": {"source": "film"}}, "instrument.settings.profile"),
        ({"sample_noise_pm": -1}, "instrument.settings.sample_noise_pm"),
        ({"q_bounds": [5, 500]}, "instrument.settings.q_bounds: Extra inputs are not permitted"),
    ],
)
def test_bad_pfm_settings_are_rejected_by_the_driver_naming_the_field(instrument, field):
    config = parse_config({"instrument": {"kind": "pfm", "settings": instrument}})
    with pytest.raises(ConfigError, match=field):
        validated(config)


def test_measuring_outside_the_profile_is_an_error():
    with pytest.raises(ValueError, match="outside the profile"):
        PFMInstrument(SYNTH).measure(np.array([1.5]), 0.1)
