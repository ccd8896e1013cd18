"""The one line a check prints, and how it tells an empty scaffold."""

from __future__ import annotations


def report(ok: bool, correct: str, hint: str) -> bool:
    """Print the one line of a check and return ``ok``."""
    print(f"correct: {correct}" if ok else f"not yet: {hint}")
    return bool(ok)


def say(ok: bool, correct: str, hint: str) -> None:
    """:func:`report`, returning nothing: for a check called as a cell's last
    line, whose value would show as a second output (a trailing ``;`` does
    not hide it under nbval)."""
    report(ok, correct, hint)


def unanswered(answer) -> bool:
    """True when the scaffold still holds its placeholder (``None`` or ``...``)."""
    return answer is None or answer is Ellipsis
