"""The schedule's modes (``schedule.mode``): how a campaign spends shots on learning its noise law.

One class per mode behind ``ScheduleMode``; ``ScheduleConfig.rule`` is the config's mode as one of
these objects, and the core asks it what the mode means instead of comparing its name.

- ``paper`` (the paper's protocol): seed points, and every point until the noise model
  converges, take ``shots_before`` shots and their sample sd is the point's measured noise;
  then ``shots_after``.
- ``budget``: every point, seeds included, takes ``shots_after`` (at least 2) shots and the
  noise model learns from every point's replicate scatter.
"""

from __future__ import annotations

from typing import ClassVar, Protocol


class ScheduleMode(Protocol):
    name: ClassVar[str]
    every_point_teaches_noise: ClassVar[bool]
    """Whether every point informs the noise law through its replicate scatter (so a point's own
    noise never stands in for the model's)."""
    intact_noise_shots: ClassVar[int | None]
    """The shots a point must keep, losing none to rejection, to inform the noise law whatever it
    was planned with; None where only noise-measuring points do."""

    def seed_shots(self, shots_before: int, shots_after: int) -> int:
        """The shots a seed point takes."""
        ...

    def shots(self, converged: bool, shots_before: int, shots_after: int) -> int:
        """The shots the schedule gives the next point."""
        ...

    def measures_noise(self, converged: bool, shots: int) -> bool:
        """Whether a point of ``shots`` shots is a noise measurement (its sample sd its noise)."""
        ...

    def rechecks_interval(self, posterior_rule: bool) -> bool:
        """Whether the posterior of the optimal t is judged afresh each step (an interval that
        narrowed can widen again), rather than once converged for good."""
        ...

    def check(self, shots_after: int, adaptive_shots: bool) -> None:
        """Raise ValueError for schedule settings the mode cannot work with."""
        ...


class Paper:
    name: ClassVar[str] = "paper"
    every_point_teaches_noise: ClassVar[bool] = False
    intact_noise_shots: ClassVar[int | None] = None

    def seed_shots(self, shots_before: int, shots_after: int) -> int:
        return shots_before

    def shots(self, converged: bool, shots_before: int, shots_after: int) -> int:
        return shots_after if converged else shots_before

    def measures_noise(self, converged: bool, shots: int) -> bool:
        return not converged and shots >= 2

    def rechecks_interval(self, posterior_rule: bool) -> bool:
        return False

    def check(self, shots_after: int, adaptive_shots: bool) -> None:
        return None


class Budget:
    name: ClassVar[str] = "budget"
    every_point_teaches_noise: ClassVar[bool] = True
    intact_noise_shots: ClassVar[int | None] = 2

    def seed_shots(self, shots_before: int, shots_after: int) -> int:
        return shots_after

    def shots(self, converged: bool, shots_before: int, shots_after: int) -> int:
        return shots_after

    def measures_noise(self, converged: bool, shots: int) -> bool:
        return False

    def rechecks_interval(self, posterior_rule: bool) -> bool:
        # A budget-mode point takes its few shots either way, so narrowing t* costs no extra
        # shots; the paper's protocol leaves its 30-shot points for good once converged.
        return posterior_rule

    def check(self, shots_after: int, adaptive_shots: bool) -> None:
        if shots_after < 2:
            raise ValueError(
                "mode: budget learns the noise from each point's replicate scatter; set shots_after to at least 2"
            )
        if adaptive_shots:
            raise ValueError(
                "mode: budget gives every point shots_after shots; adaptive_shots belongs to the paper "
                "mode's noise-measuring points"
            )


SCHEDULE_MODES: dict[str, ScheduleMode] = {mode.name: mode for mode in (Paper(), Budget())}
