"""Exceptions raised by the toolkit for bad input (all are ``ValueError`` subclasses)."""

from __future__ import annotations

__all__ = ["DomainError", "InputError", "UnknownMetricError", "short"]


class InputError(ValueError):
    """Malformed input: wrong shape or dimension, non-finite values, impossible options."""


class DomainError(InputError):
    """A point lies outside the metric's coordinate domain."""


class UnknownMetricError(InputError, KeyError):
    """No metric is registered under the requested name, or a parameter is unknown."""

    def __str__(self) -> str:  # KeyError would quote the message
        return str(self.args[0]) if self.args else ""


def short(text: str, limit: int = 48) -> str:
    """``text`` for an error message: at most ``limit`` characters (the middle replaced by
    ``...``), newlines and other control characters escaped, so that echoing a user's input
    keeps the message on one short line."""
    text = str(text)
    if not text.isprintable():
        text = text.encode("unicode_escape", "backslashreplace").decode("ascii")
    if len(text) <= limit:
        return text
    keep = max(limit - 3, 2)
    return text[: keep - keep // 3] + "..." + text[len(text) - keep // 3:]
