import numpy as np
import pytest

from noisebo.sho import fit_sho, sho_amplitude, sho_phase

F0, Q = 372_000.0, 250.0


def sweep(n, amplitude=70.0, noise=5000.0, seed=0, sign=1.0):
    rng = np.random.default_rng(seed)
    freq = np.linspace(F0 - 5000, F0 + 5000, n)
    model = sho_amplitude(freq, amplitude, F0, Q)
    amp = model + noise * rng.standard_normal(n)
    domain = 0.0 if sign > 0 else np.pi
    phase = np.rad2deg(domain + sho_phase(freq, F0, Q) + noise / (model + noise) * rng.standard_normal(n))
    return freq, amp.astype(np.float32), np.rad2deg(np.angle(np.exp(1j * np.deg2rad(phase)))).astype(np.float32)


def test_eq8_peaks_at_q_times_the_amplitude():
    assert sho_amplitude(np.array([F0]), 2.0, F0, Q)[0] == pytest.approx(2.0 * Q)
    assert sho_amplitude(np.array([0.0]), 2.0, F0, Q)[0] == pytest.approx(2.0)  # quasi-static limit
    assert sho_phase(np.array([F0]), F0, Q)[0] == pytest.approx(-np.pi / 2)


@pytest.mark.parametrize("n", [1000, 5000, 20000])  # t = 0.1, 0.5 and 2 s at 10 kHz
def test_fit_recovers_known_parameters_across_the_t_range(n):
    fit = fit_sho(*sweep(n))
    assert fit.ok and fit.reason == ""
    # tolerances: 5 standard errors (se ~2.5 pm at 1000 samples, ~0.6 at 20 000)
    assert abs(fit.amplitude - 70.0) < 5 * fit.amplitude_se
    assert abs(fit.resonance_hz - F0) < 5 * fit.resonance_se and abs(fit.q - Q) < 5 * fit.q_se
    assert fit.sign == 1.0 and fit.value == fit.amplitude


def test_noiseless_sweep_is_recovered_exactly():
    freq = np.linspace(F0 - 5000, F0 + 5000, 2000)
    fit = fit_sho(freq, sho_amplitude(freq, 42.0, 371_500.0, 180.0))
    assert fit.ok
    np.testing.assert_allclose([fit.amplitude, fit.resonance_hz, fit.q], [42.0, 371_500.0, 180.0], rtol=1e-6)


def test_negative_domain_gets_a_negative_value():
    fit = fit_sho(*sweep(2000, sign=-1.0))
    assert fit.ok and fit.sign == -1.0 and fit.value == pytest.approx(-fit.amplitude)


def test_reported_standard_error_matches_the_scatter_of_repeated_sweeps():
    """Calibration: the fit's amplitude se against the sd of fitted amplitudes over 200 sweeps."""
    for n in (1000, 20000):
        fits = [fit_sho(*sweep(n, seed=s)) for s in range(200)]
        amplitudes = np.array([f.amplitude for f in fits])
        ratio = np.mean([f.amplitude_se for f in fits]) / amplitudes.std(ddof=1)
        assert all(f.ok for f in fits) and 0.8 <= ratio <= 1.2, (n, ratio)


@pytest.mark.parametrize(
    "freq, amp, reason",
    [
        (np.linspace(1, 2, 10), np.ones(10), "10 samples; a fit needs at least 16"),
        (np.linspace(1, 2, 50), np.full(50, np.nan), "non-finite samples"),
        (np.linspace(2, 1, 50), np.ones(50), "frequencies must increase"),
        (np.linspace(1, 2, 50), np.ones(40), "equal-length 1-D arrays"),
        (np.linspace(1, 2, 50), np.zeros(50), "flat spectrum"),
    ],
)
def test_bad_sweeps_are_flagged_never_silent(freq, amp, reason):
    fit = fit_sho(freq, amp)
    assert not fit.ok and reason in fit.reason and fit.reason
    assert np.isnan(fit.value)


def test_nominal_resonance_rescues_a_buried_response():
    freq, amp, phase = sweep(1000, amplitude=3.0, noise=8000.0, seed=3)
    free = fit_sho(freq, amp, phase)
    rescued = fit_sho(freq, amp, phase, nominal=(F0, Q))
    assert not free.ok  # this draw (seed 3) buries the response: the free fit fails
    assert rescued.ok and rescued.reason.startswith("nominal resonance") and np.isfinite(rescued.amplitude_se)
    assert abs(rescued.amplitude - 3.0) < 5 * rescued.amplitude_se
