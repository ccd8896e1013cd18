"""What the command line prints for people: its help, wrapped to the terminal with the examples kept whole so
that they can be copied; a run's verdict, each reason of the trust flag on lines of its own; and a
command's report, which must reach standard output (:func:`say`)."""

from __future__ import annotations

import argparse
import os
import re
import sys

from helpers.errors import SlamError


class HelpFormatter(argparse.HelpFormatter):
    """argparse's help, each line of a description or epilog wrapped on its own; an indented line (an example
    command) is kept whole."""

    def _fill_text(self, text: str, width: int, indent: str) -> str:
        return "\n".join(
            indent + line if line.startswith(" ") else super(HelpFormatter, self)._fill_text(line, width, indent)
            for line in text.splitlines()
        )


class Parser(argparse.ArgumentParser):
    """An ArgumentParser whose help, and its subcommands' (they are made of the same class), uses
    :class:`HelpFormatter`."""

    def __init__(self, *args, formatter_class=HelpFormatter, **kwargs):
        super().__init__(*args, formatter_class=formatter_class, **kwargs)


def example(*commands: str) -> str:
    """An epilog of example commands, one a line."""
    return ("example:\n" if len(commands) == 1 else "examples:\n") + "\n".join(f"  {c}" for c in commands)


def reason_lines(problem: str, heading: str = "not trusted") -> list[str]:
    """A reason of the trust flag as short lines: what went wrong on a ``warning:`` line of its own (under
    ``heading``), then its likely cause and what to change, a sentence a line, indented under it."""
    what, *rest = re.split(r"(?<=\.)\s+(?=[A-Z])", problem.strip())
    return [f"warning: {heading}: {what}", *(f"  {sentence}" for sentence in rest)]


def verdict(problems: list[str], scale: str = "") -> str:
    """A run's last line: whether its result can be trusted (the reasons are the warnings before it), or
    trusted in shape only, when nothing but its scale is unobserved (``scale``: why, as
    :class:`helpers.quality.trust.Health` says it)."""
    if problems:
        reasons = f"{len(problems)} reason{'s' if len(problems) > 1 else ''}"
        return f'not trusted: {reasons} in the warnings above (metrics.json: "trusted": false)'
    if scale:
        return (
            "trusted in shape only: its scale is not observed, see the warning above "
            '(metrics.json: "trusted": false, "shape_trusted": true)'
        )
    return "trusted"


class StreamError(Exception):
    """Standard output could not take the report (full, or closed) of a command whose outputs are written."""


def say(*lines: str, written=None) -> None:
    """Print ``lines`` on standard output now; a :class:`StreamError` if it cannot take them (full, closed),
    saying whether the command's outputs (``written``) are already whole."""
    try:
        print("\n".join(lines), flush=True)
    except OSError as exc:
        if sys.stdout is sys.__stdout__:  # what stays in its buffer goes nowhere at exit, instead of a traceback
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, sys.stdout.fileno())
            os.close(devnull)
        if written is None:
            raise SlamError(f"cannot write to standard output: {exc.strerror or exc}") from None
        raise StreamError(f"{exc.strerror or exc}; {written} was written in full") from None


def report_run(metrics: dict, health, out) -> None:
    """A finished run's report: each reason of the trust flag on standard error first (a report that cannot
    be printed must not take the warnings with it), then its figures, the flag's counts and the verdict.
    The ATE is reported where ``metrics`` has one (a run graded against a truth)."""
    for problem in health.problems:
        print(*reason_lines(problem), sep="\n", file=sys.stderr)
    if health.scale and not health.problems:  # one verdict at a time: an untrusted run's scale is in its summary
        print(*reason_lines(health.scale, "trusted in shape only"), sep="\n", file=sys.stderr)
    graded = (
        f" ({metrics['n_false_loop_closures']} false); ATE {metrics['ate_rmse_odometry_m']:.2f} m (odometry) -> "
        f"{metrics['ate_rmse_optimized_m']:.2f} m (optimised)"
        if "ate_rmse_optimized_m" in metrics
        else "; no truth given (--truth), no ATE"
    )
    say(
        f"{metrics['n_accepted']} accepted scans of {metrics['n_scans']}, {metrics['n_loop_closures']} loop "
        f"closures{graded}; {metrics['runtime_s']['total']:.0f} s; written to {out}",
        health.summary(),
        verdict(health.problems, health.scale),
        written=out,
    )
