"""Exceptions raised by the toolkit for bad input (all are ``ValueError`` subclasses)."""

from __future__ import annotations

__all__ = ["DomainError", "InputError", "UnknownMetricError"]


class InputError(ValueError):
    """Malformed input: wrong shape or dimension, non-finite values, impossible options."""


class DomainError(InputError):
    """A point lies outside the metric's coordinate domain."""


class UnknownMetricError(InputError, KeyError):
    """No metric is registered under the requested name, or a parameter is unknown."""

    def __str__(self) -> str:  # KeyError would quote the message
        return str(self.args[0]) if self.args else ""
