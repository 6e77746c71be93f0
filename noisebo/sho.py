"""Simple-harmonic-oscillator fit of one resonance sweep (Eq. 8 of the paper).

    r(w) = r_real * w0^2 / sqrt((w^2 - w0^2)^2 + (w * w0 / Q)^2)

Frequencies enter in Hz (the form is scale-free, so w and f give the same fit); the fit runs on
frequencies divided by the sweep's centre for conditioning. Standard errors come from the
covariance s^2 (J^T J)^-1 at the optimum (s^2 the residual variance), solved by Cholesky. The
domain sign comes from the phase spectrum: the measured phase minus the oscillator's own phase lag
is the local response phase, averaged over the sweep with the model amplitude squared as weight.
A fit that cannot be trusted is flagged (``ok`` False, ``reason`` says why); its numbers are
still finite where they exist, and NaN never passes as a value.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from scipy.linalg import cho_factor, cho_solve

MIN_SAMPLES = 16


class SHOFit(NamedTuple):
    """One sweep's fit. amplitude: r_real (spectrum units, >= 0); resonance_hz: f0; q: quality
    factor; *_se: their standard errors; phase_deg: local response phase; sign: +1 or -1 from
    the phase against the reference; value: sign * amplitude; ok/reason: whether to trust it."""

    value: float
    amplitude: float
    amplitude_se: float
    resonance_hz: float
    resonance_se: float
    q: float
    q_se: float
    phase_deg: float
    sign: float
    ok: bool
    reason: str


FIT_COLUMNS = SHOFit._fields


def sho_amplitude(freq: np.ndarray, amplitude: float, resonance: float, q: float) -> np.ndarray:
    """Eq. 8 at frequencies ``freq`` (same units as ``resonance``)."""
    freq = np.asarray(freq, dtype=np.float64)
    return amplitude * resonance**2 / np.sqrt((freq**2 - resonance**2) ** 2 + (freq * resonance / q) ** 2)


def sho_phase(freq: np.ndarray, resonance: float, q: float) -> np.ndarray:
    """The oscillator's phase lag (radians, in (-pi, 0]) at ``freq``."""
    freq = np.asarray(freq, dtype=np.float64)
    return -np.arctan2(freq * resonance / q, resonance**2 - freq**2)


def model_and_jacobian(params: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    a, u0, q = params
    d = (u**2 - u0**2) ** 2 + (u * u0 / q) ** 2
    inv_sqrt = 1.0 / np.sqrt(d)
    model = a * u0**2 * inv_sqrt
    dd_du0 = -4.0 * u0 * (u**2 - u0**2) + 2.0 * u**2 * u0 / q**2
    dd_dq = -2.0 * (u * u0) ** 2 / q**3
    jac = np.empty((3, u.size))  # rows: d/d(r_real), d/du0, d/dQ; row-major keeps J J^T fast
    jac[0] = u0**2 * inv_sqrt
    jac[1] = a * (2.0 * u0 * inv_sqrt - 0.5 * u0**2 * inv_sqrt**3 * dd_du0)
    jac[2] = -0.5 * a * u0**2 * inv_sqrt**3 * dd_dq
    return model, jac


def initial_guess(u: np.ndarray, amp: np.ndarray, q_bounds: tuple[float, float]) -> np.ndarray:
    """(r_real, u0, Q) from the spectrum: peak of a smoothed copy, Q from its half-maximum width."""
    width = max(5, u.size // 100)
    smooth = np.convolve(amp, np.ones(width) / width, mode="same")
    edge = width // 2
    core = slice(edge, u.size - edge) if u.size > 2 * edge + 1 else slice(0, u.size)
    i = core.start + int(np.argmax(smooth[core]))
    peak, floor = smooth[i], float(np.median(smooth))
    half = floor + 0.5 * (peak - floor) if peak > floor else 0.5 * peak
    left = i
    while left > 0 and smooth[left] > half:
        left -= 1
    right = i
    while right < u.size - 1 and smooth[right] > half:
        right += 1
    fwhm = max(u[right] - u[left], u[1] - u[0])
    q = float(np.clip(u[i] / fwhm, *q_bounds))
    return np.array([max(peak, 1e-12) / q, u[i], q])


MAX_ITERATIONS = 200


# einsum, not BLAS: threaded BLAS calls on long vectors cost 100x more on a busy 2-core machine.
def _gram(jac: np.ndarray) -> np.ndarray:
    return np.einsum("in,jn->ij", jac, jac)


def _sum_squares(v: np.ndarray) -> float:
    return float(np.einsum("n,n->", v, v))


def _levenberg_marquardt(start, u, amp, lower, upper):
    """Bounded Levenberg-Marquardt on the 3x3 normal equations (steps projected onto the
    bounds). Returns (params, residual, jacobian) at the optimum, or a reason string."""
    x = start.copy()
    model, jac = model_and_jacobian(x, u)
    residual = model - amp
    cost = _sum_squares(residual)
    damping = 1e-3
    for _ in range(MAX_ITERATIONS):
        jtj, grad = _gram(jac), np.einsum("in,n->i", jac, residual)
        scale = np.diag(jtj).copy()
        if not np.all(np.isfinite(jtj)) or np.any(scale <= 0):
            return "degenerate Jacobian"
        while True:
            try:
                step = -cho_solve(cho_factor(jtj + damping * np.diag(scale)), grad)
            except np.linalg.LinAlgError:
                step = None
            if step is not None:
                trial = np.clip(x + step, lower, upper)
                t_model, t_jac = model_and_jacobian(trial, u)
                t_residual = t_model - amp
                t_cost = _sum_squares(t_residual)
                if np.isfinite(t_cost) and t_cost <= cost:
                    break
            damping *= 4.0
            if damping > 1e12:
                return x, residual, jac  # no downhill step left: a (possibly bounded) optimum
        moved = np.max(np.abs(trial - x) / (np.abs(x) + 1e-12))
        improved = cost - t_cost
        x, residual, jac, cost = trial, t_residual, t_jac, t_cost
        damping = max(damping / 3.0, 1e-12)
        if moved < 1e-9 or improved <= 1e-10 * cost:
            return x, residual, jac
    return "no convergence in %d iterations" % MAX_ITERATIONS


def _failed(reason: str, params=(np.nan, np.nan, np.nan)) -> SHOFit:
    a, f0, q = (float(v) for v in params)
    return SHOFit(float("nan"), a, float("nan"), f0, float("nan"), q, float("nan"), float("nan"), 0.0, False, reason)


def fit_sho(
    freq_hz: np.ndarray,
    amplitude: np.ndarray,
    phase_deg: np.ndarray | None = None,
    q_bounds: tuple[float, float] = (5.0, 5000.0),
    reference_phase_deg: float = 0.0,
    nominal: tuple[float, float] | None = None,
) -> SHOFit:
    """Fit Eq. 8 to one sweep: ``freq_hz`` (N,) increasing, ``amplitude`` (N,) in spectrum
    units, optional ``phase_deg`` (N,) for the sign. Bounds: r_real >= 0, f0 inside the sweep,
    Q in ``q_bounds``. Without a phase spectrum the sign is +1.

    ``nominal`` (f0 in Hz, Q), the resonance from the instrument's tune, rescues a sweep whose
    free fit fails (typically a weak response buried in noise): r_real is then the linear
    least-squares projection on the nominal resonance curve, with its exact standard error, and
    ``reason`` says so while ``ok`` stays True."""
    problem = _input_problem(np.asarray(freq_hz, dtype=np.float64), np.asarray(amplitude, dtype=np.float64))
    if problem:
        return _failed(problem)
    fit = _free_fit(freq_hz, amplitude, phase_deg, q_bounds, reference_phase_deg)
    if fit.ok or nominal is None:
        return fit
    return _nominal_fit(freq_hz, amplitude, phase_deg, nominal, reference_phase_deg, fit.reason)


def _input_problem(freq: np.ndarray, amp: np.ndarray) -> str:
    """Why a sweep cannot be fitted at all (empty string: it can)."""
    if freq.ndim != 1 or freq.shape != amp.shape:
        return f"frequency and amplitude must be equal-length 1-D arrays, got {freq.shape} and {amp.shape}"
    if freq.size < MIN_SAMPLES:
        return f"{freq.size} samples; a fit needs at least {MIN_SAMPLES}"
    if not (np.all(np.isfinite(freq)) and np.all(np.isfinite(amp))):
        return "non-finite samples in the sweep"
    if not np.all(np.diff(freq) > 0):
        return "frequencies must increase along the sweep"
    if np.ptp(amp) == 0:
        return "flat spectrum: no resonance"
    return ""


def _nominal_fit(freq_hz, amplitude, phase_deg, nominal, reference_phase_deg, why: str) -> SHOFit:
    f0, q = nominal
    freq = np.asarray(freq_hz, dtype=np.float64)
    amp = np.asarray(amplitude, dtype=np.float64)
    shape = sho_amplitude(freq, 1.0, f0, q)
    norm = _sum_squares(shape)
    a = float(np.einsum("n,n->", shape, amp)) / norm
    s2 = _sum_squares(amp - a * shape) / (freq.size - 1)
    se = float(np.sqrt(s2 / norm))
    centre = 0.5 * (freq[0] + freq[-1])
    phase, sign = float("nan"), 1.0
    if phase_deg is not None:
        phase, sign = _response_phase(
            freq / centre, np.asarray(phase_deg, dtype=np.float64), 1.0, f0 / centre, q, reference_phase_deg
        )
        if not np.isfinite(phase):
            return _failed("non-finite phase samples")
    value = sign * a
    return SHOFit(value, a, se, float(f0), 0.0, float(q), 0.0, phase, sign, True, f"nominal resonance ({why})")


def _free_fit(freq_hz, amplitude, phase_deg, q_bounds, reference_phase_deg) -> SHOFit:
    freq = np.asarray(freq_hz, dtype=np.float64)
    amp = np.asarray(amplitude, dtype=np.float64)
    centre = 0.5 * (freq[0] + freq[-1])
    u = freq / centre
    lower = np.array([0.0, u[0], q_bounds[0]])
    upper = np.array([np.inf, u[-1], q_bounds[1]])
    start = np.clip(initial_guess(u, amp, q_bounds), lower + 1e-12, upper - 1e-12)

    fitted = _levenberg_marquardt(start, u, amp, lower, upper)
    if isinstance(fitted, str):
        return _failed(fitted)
    x, residual, jac = fitted
    a, u0, q = x
    params = (a, u0 * centre, q)
    span = upper - lower
    for name, value, lo, hi, sp in zip(("amplitude", "resonance", "Q"), x, lower, upper, span):
        tol = 1e-6 * (sp if np.isfinite(sp) else max(abs(value), 1.0))
        if (name != "amplitude" and value - lo < tol) or value > hi - tol:
            return _failed(f"{name} at its bound ({value * (centre if name == 'resonance' else 1):.6g})", params)
    dof = freq.size - 3
    s2 = _sum_squares(residual) / dof
    jtj = _gram(jac)
    try:
        cov = s2 * cho_solve(cho_factor(jtj), np.eye(3))
    except np.linalg.LinAlgError:
        return _failed("singular fit covariance", params)
    se = np.sqrt(np.diag(cov))
    if not np.all(np.isfinite(se)) or a <= 0:
        return _failed("no finite amplitude uncertainty", params)
    phase, sign = float("nan"), 1.0
    if phase_deg is not None:
        phase, sign = _response_phase(u, np.asarray(phase_deg, dtype=np.float64), a, u0, q, reference_phase_deg)
        if not np.isfinite(phase):
            return _failed("non-finite phase samples", params)
    return SHOFit(
        value=float(sign * a),
        amplitude=float(a),
        amplitude_se=float(se[0]),
        resonance_hz=float(u0 * centre),
        resonance_se=float(se[1] * centre),
        q=float(q),
        q_se=float(se[2]),
        phase_deg=phase,
        sign=sign,
        ok=True,
        reason="",
    )


def _response_phase(u, phase_deg, a, u0, q, reference_deg) -> tuple[float, float]:
    """Amplitude-weighted circular mean of (measured phase - oscillator lag), in degrees, and the
    sign of its projection on the reference phase."""
    if phase_deg.shape != u.shape or not np.all(np.isfinite(phase_deg)):
        return float("nan"), 1.0
    weight = sho_amplitude(u, a, u0, q) ** 2
    residual = np.deg2rad(phase_deg) - sho_phase(u, u0, q)
    mean = np.angle(np.sum(weight * np.exp(1j * residual)))
    sign = 1.0 if np.cos(mean - np.deg2rad(reference_deg)) >= 0 else -1.0
    return float(np.rad2deg(mean)), sign
