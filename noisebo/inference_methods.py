"""How a campaign infers its models' hyperparameters (``inference.mode``): one class per method.

``InferenceConfig.method`` is the config's mode as one of these objects; the fit stages, the
compile-ahead thread and the config's checks ask it what the method does instead of comparing its
name.

- ``map``: L-BFGS to the posterior mode (multi-started, on binned inputs past
  ``inference.search_inputs``), the noise model with a Laplace approximation of
  ``laplace_samples`` draws. Its programs are fixed per padding capacity, so they can be compiled
  ahead of the decision that needs them. The noise field over x is fitted this way only.
- ``nuts``: numpyro's NUTS, ``nuts_samples`` posterior draws after ``nuts_warmup``; a sampler is
  per thread, so nothing is compiled ahead.
"""

from __future__ import annotations

from typing import ClassVar, Protocol


class InferenceMethod(Protocol):
    name: ClassVar[str]
    samples_posterior: ClassVar[bool]
    """Whether the fit draws from the posterior (NUTS) rather than finding its mode (MAP)."""
    compiles_ahead: ClassVar[bool]
    """Whether its programs can be compiled before the decision that needs them."""
    fits_noise_field: ClassVar[bool]
    """Whether it can fit a noise field over x (``noise_model.field``)."""

    def too_few_t_star_draws(self, laplace_samples: int, least: int) -> str | None:
        """Why the fit's draws of the optimal t are too few for the posterior convergence rule
        (``least`` wanted), or None."""
        ...


class Map:
    name: ClassVar[str] = "map"
    samples_posterior: ClassVar[bool] = False
    compiles_ahead: ClassVar[bool] = True
    fits_noise_field: ClassVar[bool] = True

    def too_few_t_star_draws(self, laplace_samples: int, least: int) -> str | None:
        if laplace_samples >= least:
            return None
        return f"set inference.laplace_samples to at least {least}"


class Nuts:
    name: ClassVar[str] = "nuts"
    samples_posterior: ClassVar[bool] = True
    compiles_ahead: ClassVar[bool] = False
    fits_noise_field: ClassVar[bool] = False

    def too_few_t_star_draws(self, laplace_samples: int, least: int) -> str | None:
        return None  # the sampler's own draws


INFERENCE_METHODS: dict[str, InferenceMethod] = {method.name: method for method in (Map(), Nuts())}
