"""Checks for the notebooks' exercises.

Each exercise in a notebook has a scaffold cell the learner fills in and a
check the learner runs. A check compares the answer with something computed
here from the data (a known transform, the simulator's poses, a library
call), prints one line and returns whether the answer holds:

    correct: <what the answer shows>
    not yet: <a hint>

An empty scaffold prints ``not yet``, so the notebooks run as shipped; the
worked answers are in ``notebooks/solutions/``, which the tests run too.
One module per notebook: :mod:`.dataset`, :mod:`.registration`, ...
"""

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
