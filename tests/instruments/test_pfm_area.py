"""The simulated PFM over an area: the scan's signed response map and its bilinear interpolation,
synthetic domain patterns, extents and shots outside them, x-dependent noise (noise_law_at and
the noisy walls that the landing jitter makes), the line unchanged, and data/configs/pfm2d.yaml."""

import h5py
import numpy as np
from pathlib import Path

import pytest
import yaml
from scipy import ndimage

from noisebo.instruments.faults import FaultyInstrument
from noisebo.instruments.pfm import PFMInstrument, PFMSettings
from noisebo.instruments.pfm_area import ScanAreaConfig, SyntheticAreaConfig
from noisebo.instruments.pfm_profile import ScanProfileConfig, SyntheticProfileConfig
from noisebo.instruments.pfm_scan import ProfileError, dominant_phase
from noisebo.instruments.registry import build, validated
from noisebo.config import ConfigError, FaultsConfig, InstrumentConfig, ReductionConfig, parse_config
from noisebo.reduction import shot_value

PROJECT_ROOT = Path(__file__).resolve().parents[2]

PITCH = 1 / 255  # um: the shipped scan's 256 pixels over 1 um
TUNED = ReductionConfig(sho={"nominal_resonance_hz": 372_000.0, "nominal_q": 250.0})
STRIPES = PFMSettings(profile=SyntheticAreaConfig(n_domains=2))


@pytest.fixture(scope="module")
def area():
    return PFMInstrument(PFMSettings(profile=ScanAreaConfig()))


@pytest.fixture(scope="module")
def signed_map():
    """The signed response (pm) of the shipped scan computed here from the raw channels: the
    amplitude (channel 1) smoothed by 1 pixel, negative where the smoothed cos(phase - dominant
    phase) (channel 3) is negative."""
    with h5py.File(PROJECT_ROOT / "data/pfm/PTO_Funakubo0003.h5") as f:
        amplitude = f["Measurement_000/Channel_1/Channel_1/Channel_1"][()].astype(np.float64)
        phase = np.deg2rad(f["Measurement_000/Channel_3/Channel_3/Channel_3"][()].astype(np.float64))
    sign = np.where(ndimage.gaussian_filter(np.cos(phase - dominant_phase(phase)), 1.0) >= 0, 1.0, -1.0)
    return ndimage.gaussian_filter(amplitude * 1e12, 1.0) * sign


def test_truth_at_pixel_centres_is_the_smoothed_signed_map(area, signed_map):
    rows = np.array([0, 0, 255, 255, 17, 128, 200, 93])
    columns = np.array([0, 255, 0, 255, 230, 64, 5, 93])
    positions = np.column_stack([columns * PITCH, rows * PITCH])  # x along columns, y along rows
    np.testing.assert_allclose(area.truth(positions), signed_map[rows, columns], rtol=1e-9, atol=1e-9)
    assert signed_map.min() < -50 and signed_map.max() > 100  # both domain signs


def test_truth_is_bilinear_between_pixels(area, signed_map):
    i, j, fy, fx = 50, 70, 0.25, 0.6  # a quarter of a pixel down, 0.6 of a pixel right
    m = signed_map
    expected = (
        (1 - fy) * (1 - fx) * m[i, j]
        + (1 - fy) * fx * m[i, j + 1]
        + fy * (1 - fx) * m[i + 1, j]
        + fy * fx * m[i + 1, j + 1]
    )
    assert area.truth(np.array([[(j + fx) * PITCH, (i + fy) * PITCH]]))[0] == pytest.approx(expected, rel=1e-9)


@pytest.mark.parametrize(
    "line, along",
    [
        ({"start_px": [40, 0], "end_px": [40, 255]}, "row"),
        ({"start_px": [0, 100], "end_px": [255, 100]}, "column"),
    ],
)
def test_a_line_and_the_area_share_the_map(area, line, along):
    profile = PFMInstrument(PFMSettings(profile=ScanProfileConfig(**line)))
    s = np.linspace(0.0, 1.0, 37)
    points = (
        np.column_stack([s, np.full_like(s, 40 * PITCH)])
        if along == "row"
        else np.column_stack([np.full_like(s, 100 * PITCH), s])
    )
    np.testing.assert_allclose(area.truth(points), profile.truth(s[:, None]), rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize(
    "source, dimensions, bounds",
    [
        (ScanAreaConfig(), 2, [(0.0, 1.0), (0.0, 1.0)]),
        (
            ScanAreaConfig(rows_px=(10, 137), columns_px=(20, 147)),
            2,
            [(20 * PITCH, 147 * PITCH), (10 * PITCH, 137 * PITCH)],
        ),
        (SyntheticAreaConfig(size_um=(2.0, 0.5)), 2, [(0.0, 2.0), (0.0, 0.5)]),
        (ScanProfileConfig(), 1, [(0.0, np.hypot(180, 135) / 255)]),
        (SyntheticProfileConfig(length_um=3.0), 1, [(0.0, 3.0)]),
    ],
    ids=["whole scan", "sub-rectangle", "synthetic area", "scan line", "synthetic line"],
)
def test_extents(source, dimensions, bounds):
    inst = PFMInstrument(PFMSettings(profile=source))
    assert inst.dimensions == dimensions and len(inst.bounds_um) == dimensions and inst.bounds == inst.bounds_um
    np.testing.assert_allclose(inst.bounds_um, bounds, rtol=1e-12)


@pytest.mark.parametrize(
    "source, x, message",
    [
        (ScanAreaConfig(), [1.01, 0.5], r"x=\(1.01, 0.5\) um lies outside the area \[0, 1\] x \[0, 1\] um"),
        (ScanAreaConfig(), [0.5, -0.01], r"x=\(0.5, -0.01\) um lies outside the area"),
        (
            ScanAreaConfig(rows_px=(10, 137), columns_px=(20, 147)),
            [0.05, 0.1],
            r"x=\(0.05, 0.1\) um lies outside the area \[0.07843, 0.5765\] x \[0.03922, 0.5373\] um",
        ),
        (SyntheticAreaConfig(size_um=(2.0, 0.5)), [1.5, 0.6], r"outside the area \[0, 2\] x \[0, 0.5\] um"),
        (ScanAreaConfig(), [0.5], r"PFM sweep needs 2 finite coordinates \(x_um, y_um\) and t > 0, got x=\[0.5\]"),
        (ScanAreaConfig(), [0.5, float("nan")], "PFM sweep needs 2 finite coordinates"),
        (SyntheticProfileConfig(), [0.5, 0.5], r"PFM sweep needs one finite coordinate \(um\)"),
    ],
    ids=[
        "right of the scan",
        "above the scan",
        "before a sub-rectangle",
        "synthetic",
        "one coordinate",
        "nan",
        "two on a line",
    ],
)
def test_a_shot_outside_the_extent_names_x_and_the_extent(source, x, message):
    with pytest.raises(ValueError, match=message):
        PFMInstrument(PFMSettings(profile=source)).measure(np.array(x), 0.1)


def test_positions_of_the_wrong_width_are_refused(area):
    with pytest.raises(ValueError, match=r"PFM truth needs positions \(n, 2\) in um, got shape \(3, 1\)"):
        area.truth(np.zeros((3, 1)))
    with pytest.raises(ValueError, match=r"PFM positions need 2 coordinate\(s\) \(um\) each, got shape \(4,\)"):
        area.static_sd(np.zeros(4))
    line = PFMInstrument(PFMSettings(profile=SyntheticProfileConfig()))
    with pytest.raises(ValueError, match=r"PFM positions need 1 coordinate\(s\) \(um\) each, got shape \(3, 2\)"):
        line.noise_law_at(np.zeros((3, 2)), np.array([1.0]))


@pytest.mark.parametrize(
    "profile, error, message",
    [
        (
            {"source": "scan_area", "rows_px": [0, 300]},
            ProfileError,
            r"rows_px \(0, 300\) lies outside the 256 x 256 scan",
        ),
        (
            {"source": "scan_area", "columns_px": [5, 5]},
            ConfigError,
            "columns_px: the first pixel \\(5\\) must be below",
        ),
        ({"source": "scan_area", "rows_px": [-1, 5]}, ConfigError, "instrument.settings.profile.scan_area.rows_px"),
        (
            {"source": "synthetic_area", "size_um": [1.0, 0.0]},
            ConfigError,
            "instrument.settings.profile.synthetic_area.size_um",
        ),
        (
            {"source": "synthetic_area", "pattern": "spiral"},
            ConfigError,
            "instrument.settings.profile.synthetic_area.pattern",
        ),
        ({"source": "scan_area", "start_px": [0, 0]}, ConfigError, "start_px: Extra inputs are not permitted"),
    ],
    ids=["rows beyond the scan", "empty columns", "negative row", "zero height", "unknown pattern", "a line's setting"],
)
def test_bad_area_sources_name_the_field(profile, error, message):
    with pytest.raises(error, match=message):
        config = validated(parse_config({"instrument": {"kind": "pfm", "settings": {"profile": profile}}}))
        build(config.instrument)


@pytest.mark.parametrize(
    "pattern, angle, signs",
    [
        ("stripes", 0.0, {(0.25, 0.1): 1, (0.25, 0.9): 1, (0.75, 0.1): -1, (0.75, 0.9): -1}),
        ("stripes", 90.0, {(0.1, 0.25): 1, (0.9, 0.25): 1, (0.1, 0.75): -1, (0.9, 0.75): -1}),
        ("checker", 0.0, {(0.25, 0.25): 1, (0.75, 0.25): -1, (0.25, 0.75): -1, (0.75, 0.75): 1}),
    ],
)
def test_synthetic_domains_alternate_in_sign_and_vanish_at_walls(pattern, angle, signs):
    inst = PFMInstrument(PFMSettings(profile=SyntheticAreaConfig(pattern=pattern, angle_deg=angle, n_domains=2)))
    values = inst.truth(np.array(list(signs)))
    assert np.all(np.sign(values) == list(signs.values())) and np.all(np.abs(values) > 50)
    wall = [[0.5, 0.3]] if (pattern, angle) == ("stripes", 0.0) else [[0.3, 0.5]]
    assert abs(inst.truth(np.array(wall))[0]) < 1e-9


def test_stripes_across_x_are_the_synthetic_line_at_every_y():
    # the same seed draws the same domain amplitudes; the line is sampled every 0.0005 um
    line = PFMInstrument(PFMSettings(profile=SyntheticProfileConfig(n_domains=3, seed=4)))
    stripes = PFMInstrument(PFMSettings(profile=SyntheticAreaConfig(n_domains=3, seed=4)))
    x = np.linspace(0.0, 1.0, 201)  # on the line's grid
    for y in (0.0, 0.37, 1.0):
        np.testing.assert_allclose(
            stripes.truth(np.column_stack([x, np.full_like(x, y)])), line.truth(x[:, None]), rtol=1e-12, atol=1e-9
        )


def test_area_sweeps_measure_the_local_response_and_are_deterministic():
    inst = build(InstrumentConfig(kind="pfm", settings=STRIPES.model_dump(mode="json")))
    a = inst.simulate(np.array([0.25, 0.4]), 0.2, np.random.default_rng(3))
    b = inst.simulate(np.array([0.25, 0.4]), 0.2, np.random.default_rng(3))
    assert a.spectrum.shape == (3, 2000) and a.reduction == "sho"
    np.testing.assert_array_equal(a.spectrum, b.spectrum)
    rng = np.random.default_rng(0)
    for x in ([0.25, 0.4], [0.75, 0.9]):
        values = [shot_value(inst.simulate(np.array(x), 1.0, rng), TUNED).value for _ in range(12)]
        law = inst.noise_law_at(np.array([x]), np.array([1.0]))[0, 0]
        assert np.mean(values) == pytest.approx(inst.truth(np.array([x]))[0], abs=4 * law / np.sqrt(12))


@pytest.mark.parametrize(
    "source, positions",
    [
        (SyntheticProfileConfig(n_domains=2), np.array([[0.0], [0.25], [0.5], [1.0]])),
        (
            SyntheticAreaConfig(pattern="checker", n_domains=3),
            np.array([[0.0, 0.0], [0.5, 0.5], [1 / 3, 0.2], [1.0, 0.7]]),
        ),
    ],
    ids=["line", "area"],
)
def test_noise_law_at_is_the_noise_law_where_the_static_noise_is_uniform(source, positions):
    # no landing or gain jitter: the static sd is the background's everywhere
    inst = PFMInstrument(PFMSettings(profile=source, position_jitter_um=0.0, gain_jitter=0.0, background_pm=0.7))
    t = np.array([0.1, 0.4, 2.0])
    at = inst.noise_law_at(positions, t)
    assert at.shape == (4, 3)
    np.testing.assert_allclose(at, np.broadcast_to(inst.noise_law(t), (4, 3)), rtol=1e-9)
    np.testing.assert_allclose(inst.static_sd(positions), 0.7, rtol=1e-9)


@pytest.mark.parametrize("source", [ScanProfileConfig(), SyntheticAreaConfig(pattern="checker")], ids=["line", "area"])
def test_the_noise_law_is_the_mean_square_of_noise_law_at(source):
    inst = PFMInstrument(PFMSettings(profile=source, position_jitter_um=0.002))
    t = np.array([0.1, 1.0])
    at = inst.noise_law_at(inst.averaging_positions(), t)
    np.testing.assert_allclose(np.mean(at**2, axis=0), inst.noise_law(t) ** 2, rtol=1e-12)
    # x-dependent: the walls stand out above the law, the domains' middles below it
    assert at[:, 1].max() > 3 * inst.noise_law(t)[1] and at[:, 1].min() < inst.noise_law(t)[1]


def wall_sd_by_integration(jitter_um, gain, background, wall_um=0.02, amplitude_pm=100.0, seed=0):
    """The static sd at the wall between the first two synthetic domains, from the definition:
    r(0.5 + u) = s0 tanh(-u/w) for u < 0 and -s1 tanh(u/w) for u > 0 (s0, s1 the domains'
    amplitudes), Var[(1 + g e) r + b] = (1 + g^2) E r^2 - (E r)^2 + b^2 over u ~ N(0, jitter^2),
    integrated on a fine grid (trapezoid rule), not by the driver's quadrature."""
    s0, s1 = amplitude_pm * np.random.default_rng(seed).uniform(0.6, 1.4, 2)
    u = np.linspace(-10 * jitter_um, 10 * jitter_um, 200_001)
    r = np.where(u < 0, s0 * np.tanh(-u / wall_um), -s1 * np.tanh(u / wall_um))
    pdf = np.exp(-0.5 * (u / jitter_um) ** 2) / (jitter_um * np.sqrt(2 * np.pi))
    mean, second = np.trapezoid(r * pdf, u), np.trapezoid(r**2 * pdf, u)
    return np.sqrt((1 + gain**2) * second - mean**2 + background**2), s0


@pytest.mark.parametrize(
    "source, wall, middle",
    [
        (SyntheticProfileConfig(n_domains=2), [0.5], [0.25]),
        (SyntheticAreaConfig(n_domains=2), [0.5, 0.37], [0.25, 0.37]),
    ],
    ids=["line", "stripes"],
)
def test_a_landing_jitter_of_2_5_nm_makes_the_wall_about_20_times_noisier(source, wall, middle):
    inst = PFMInstrument(PFMSettings(profile=source, position_jitter_um=0.0025))
    expected_wall, s0 = wall_sd_by_integration(0.0025, inst.config.gain_jitter, inst.config.background_pm)
    at_wall, at_middle = inst.static_sd(np.array([wall, middle]))
    assert at_wall == pytest.approx(expected_wall, rel=0.02)
    # in a domain's middle the response is flat: the gain jitter and background alone
    r = s0 * np.tanh(0.25 / 0.02)
    assert at_middle == pytest.approx(np.sqrt((0.002 * r) ** 2 + 0.5**2), rel=1e-6)
    assert 20 <= at_wall / at_middle <= 23
    # noise_law_at adds the same fit variance to each: the difference of squares is the static one's
    at = inst.noise_law_at(np.array([wall, middle]), np.array([0.5]))[:, 0]
    assert at[0] ** 2 - at[1] ** 2 == pytest.approx(at_wall**2 - at_middle**2, rel=1e-9)


def test_on_the_scan_the_landing_jitter_makes_the_steepest_place_the_noisiest(area, signed_map):
    shaky = PFMInstrument(PFMSettings(profile=ScanAreaConfig(), position_jitter_um=0.001))
    gy, gx = np.gradient(signed_map)
    steep, flat = (
        np.unravel_index(np.argmax(np.hypot(gx, gy)), gx.shape),
        np.unravel_index(np.argmin(np.hypot(gx, gy)), gx.shape),
    )
    at = shaky.static_sd(np.array([[steep[1] * PITCH, steep[0] * PITCH], [flat[1] * PITCH, flat[0] * PITCH]]))
    # where the map is flattest the sd stays near the floor of the gain jitter and the background
    assert at[1] < 1.1 * np.hypot(0.002 * signed_map[flat], 0.5) and at[0] > 10 * at[1]
    # the default settings keep the scan's static noise nearly uniform, as the noise model assumes
    assert np.quantile(area.static_sd(area.averaging_positions()), 0.99) < 1.5 * area.config.background_pm


def test_the_line_shots_and_noise_law_are_those_of_before_the_areas():
    # values recorded from the line-only driver (same settings, same random streams)
    scan = PFMInstrument(PFMSettings())
    sweep = scan.simulate(np.array([0.1]), 0.1, np.random.default_rng(1)).spectrum
    assert sweep[1, :3].tolist() == [8833.0419921875, 5394.65185546875, -1976.3221435546875]
    assert float(sweep[1].astype(np.float64).sum()) == pytest.approx(4959738.318470955, rel=1e-12)
    np.testing.assert_allclose(
        scan.noise_law(np.array([0.1, 0.3, 1.0, 2.0])),
        [4.038423569984201, 2.377593380511324, 1.3876314053899628, 1.0615697500118608],
        rtol=1e-12,
    )
    synth = PFMInstrument(
        PFMSettings(profile=SyntheticProfileConfig(n_domains=3), position_jitter_um=0.003, gain_jitter=0.01)
    )
    sweep = synth.simulate(np.array([0.4321]), 0.15, np.random.default_rng(2)).spectrum
    assert sweep[1, :3].tolist() == [16561.66015625, 11649.091796875, 631.1796875]
    np.testing.assert_allclose(
        synth.static_sd(np.linspace(0, 1, 57)[[10, 19, 28]]),
        [1.2170222526130028, 11.186864128901664, 0.9568580684102872],
        rtol=1e-9,
    )


def test_the_fault_injector_passes_an_area_through():
    inst = FaultyInstrument(PFMInstrument(STRIPES), FaultsConfig(outlier=1.0, outlier_sd=10.0))
    x, t = np.array([0.25, 0.4]), 0.5
    clean = inst.inner.simulate(x, t, np.random.default_rng(0))
    moved = inst.simulate(x, t, np.random.default_rng(0))
    scale = moved.spectrum[1] / clean.spectrum[1]
    truth = inst.truth(x[None, :])[0]
    assert scale == pytest.approx(1 + inst.ledger[0]["sign"] * 10 * inst.noise_law(np.array([t]))[0] / truth, rel=1e-5)
    assert inst.ledger[0]["x"] == [0.25, 0.4]
    np.testing.assert_array_equal(
        inst.noise_law_at(x[None, :], np.array([t])), inst.inner.noise_law_at(x[None, :], [t])
    )


def test_the_pfm2d_config_builds_the_whole_scan_and_its_axes_match_the_extent():
    config = yaml.safe_load((PROJECT_ROOT / "data/configs/pfm2d.yaml").read_text())
    line = yaml.safe_load((PROJECT_ROOT / "data/configs/pfm.yaml").read_text())
    inst = build(InstrumentConfig(kind=config["instrument"]["kind"], settings=config["instrument"]["settings"]))
    axes = config["space"]["axes"]
    assert inst.dimensions == len(axes) == 2 and [a["name"] for a in axes] == ["x", "y"]
    np.testing.assert_allclose(inst.bounds_um, [(a["low"], a["high"]) for a in axes], rtol=1e-12)
    assert all(a["units"] == "um" and a["n"] == 64 for a in axes)
    assert (config["space"]["t_min"], config["space"]["t_max"], config["space"]["n_t"]) == (0.1, 2.0, 100)
    assert (config["schedule"]["n_seed"], config["schedule"]["n_steps"]) == (6, 40)
    for section in ("reduction", "reward", "acquisition", "noise_model", "inference"):
        assert config[section] == line[section], section
    profile = {k: v for k, v in config["instrument"]["settings"].items() if k != "profile"}
    assert profile == {k: v for k, v in line["instrument"]["settings"].items() if k != "profile"}
    assert config["instrument"]["settings"]["profile"]["file"] == line["instrument"]["settings"]["profile"]["file"]
