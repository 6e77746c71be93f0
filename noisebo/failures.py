"""Instrument failures and the campaign's failure budget (pure)."""

from __future__ import annotations


class InstrumentError(RuntimeError):
    """A transient instrument failure: the shot is tried again, within the failure budget."""


class InstrumentTimeout(InstrumentError):
    """The instrument did not answer within its timeout."""


class MeasurementStopped(RuntimeError):
    """The instrument stopped waiting for a shot that nothing was measuring, because the
    campaign was asked to stop (a signal): the campaign records the status "aborted" with this
    reason, and the shot stays wanted."""


class InstrumentUnavailable(RuntimeError):
    """The instrument could not be opened for a campaign; nothing was measured."""


class FailureBudgetExceeded(RuntimeError):
    """Too many shots failed: the campaign stops instead of looping."""


def budget_message(n_failed: int, n_attempts: int, min_failed: int, tolerated_rate: float) -> str | None:
    """Why the budget is exceeded once at least ``min_failed`` of ``n_attempts`` shot attempts
    failed and their fraction exceeds ``tolerated_rate``; None while it holds."""
    if n_failed >= min_failed and n_attempts > 0 and n_failed / n_attempts > tolerated_rate:
        return (
            f"failure budget exceeded: {n_failed} of {n_attempts} shot attempts failed "
            f"({100 * n_failed / n_attempts:.0f} % > {100 * tolerated_rate:.0f} % tolerated, after at least {min_failed})"
        )
    return None


def check_budget(n_failed: int, n_attempts: int, min_failed: int, tolerated_rate: float) -> None:
    """Raise ``FailureBudgetExceeded`` when ``budget_message`` says the budget is exceeded."""
    message = budget_message(n_failed, n_attempts, min_failed, tolerated_rate)
    if message is not None:
        raise FailureBudgetExceeded(message)
