"""An instrument's noise profile: the posterior of its noise law distilled from finished
campaigns on it, with the driver (name, version, settings) and the campaigns it came from.

A microscope's or a detector's noise is a property of the instrument that changes slowly, so
what one campaign learned of Noise(t) is worth keeping. ``distil`` pools the noise measurements
of several campaigns (each point's t, the sample sd of its shots and their number) and fits the
campaigns' noise law to them once, as a campaign's noise model does (the law plus its residual
GP, the sampling variance of a sample sd in the likelihood); the MAP fit's Laplace draws give
each law parameter's posterior mean and sd, in the noise's units.
"""

from __future__ import annotations

import jax
import numpy as np

from noisebo.config import (  # noqa: F401 - the profile's records, re-exported
    PROFILE_KIND,
    CampaignConfig,
    NoiseProfile,
    ParameterPosterior,
    ProfileCampaign,
    ProfileDriver,
)
from noisebo.models import inference, noise_model

LAPLACE_DRAWS = 256  # posterior draws the parameters' mean and sd are taken over


class NotDistillable(ValueError):
    """Campaigns that no profile can be made of; the message says why."""


def distil(
    config: CampaignConfig, t: np.ndarray, shot_std: np.ndarray, n_shots: np.ndarray, key: jax.Array
) -> dict[str, ParameterPosterior]:
    """The posterior of the noise law of ``config.noise_model`` fitted to pooled noise
    measurements: t (n,) s, the sample sd of each point's shots (n,) in value units, and their
    number (n,). Returns "a0", "a1" (value units) and, for a law with an exponent, "p", each as
    mean and sd over the MAP fit's Laplace draws (``LAPLACE_DRAWS``, the MAP point first).
    Raises ``NotDistillable`` for fewer than two distinct t or non-finite measurements."""
    t, shot_std, n_shots = (np.asarray(a, dtype=np.float64) for a in (t, shot_std, n_shots))
    if config.noise_model.field is not None:
        raise NotDistillable("its noise depends on x (noise_model.field); a profile holds a noise law over t only")
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(shot_std)) and np.all(n_shots >= 2)):
        raise NotDistillable("a noise measurement is not finite or has fewer than 2 shots")
    if np.unique(t).size < 2:
        raise NotDistillable(f"the noise was measured at {np.unique(t).size} distinct t; a law needs at least 2")
    s, inf = config.space, config.inference
    t_min, t_max = min(s.t_min, float(t.min())), max(s.t_max, float(t.max()))
    own = config.noise_model.model_copy(update={"profile": None})  # the campaigns' data alone, not their prior
    data, scale, _ = noise_model.prepare(t, shot_std, n_shots, own, t_min, t_max, inf.max_inputs)
    model = noise_model.make_model(own)
    guess = noise_model.initial_guess(data, own)
    name, depends_on = noise_model.program_name(own)
    fitted = inference.fit_map(model, data, key, inf.restarts, LAPLACE_DRAWS, [guess], name=name, depends_on=depends_on)
    out = {}
    for name in ("a0", "a1", "p"):
        if name not in fitted.params:
            continue
        draws = np.asarray(fitted.params[name], dtype=np.float64) * (scale if name in ("a0", "a1") else 1.0)
        out[name] = ParameterPosterior(mean=float(draws.mean()), sd=float(draws.std()))
    return out
