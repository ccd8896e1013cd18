"""docs/CONFIGURATION.md, built from the configuration's own help text so that it cannot go stale.

Run ``python -m helpers.config.reference_doc`` in the checkout after changing a table; ``tests/test_readme.py``
fails while the file and :func:`markdown` differ.
"""

from __future__ import annotations

import inspect
import json
from pathlib import Path

from helpers.config.tables import REFERENCE_WORKFLOW, STAGE_TABLES, Config, describe

DOC = Path(__file__).resolve().parents[2] / "docs" / "CONFIGURATION.md"

INTRO = """\
# The configuration

This file is generated from the code by `python -m helpers.config.reference_doc`. Do not edit it by hand:
`tests/test_readme.py` fails when it and the code disagree.

Every tunable value lives in `helpers.config.Config`, one table per stage, in the workflow's order. The
defaults are the reference's values, or ours where we measured better. Each key carries its meaning and, where
the reference has one, the reference's (MATLAB) name; `helpers.config.describe(table)` lists them. `[sensor]`
is the simulator's table; each SLAM stage reads only its own. `python -m helpers run --config FILE` reads a
TOML file that sets only what it changes:

```toml
[registration]
skip_frames = 1
[loop_closure]
sub_map_thresh = 5
```

Unknown tables or keys, values of the wrong type and values outside their bounds are refused with one `error:`
line (`helpers/config/bounds.py` says why each bound is where it is). A file of an earlier version, with one
flat `[slam]` table, is refused with the new place of each of its keys. Before it runs, `run` fits the values
that are lengths in disguise to the flight and prints each with its reason; values your file sets are kept
([Your own data](YOUR_OWN_DATA.md)). A run writes the whole configuration it used to `config.toml`.
"""

REFERENCE_INTRO = """\
## The reference's workflow

Where our defaults differ from the reference's workflow, the reference's values are one configuration away:
`Config.reference()` in Python, or this file given to `run --config` (notebook 7 runs both on the same
flight; [REFERENCE.md](REFERENCE.md) says why each value changed):
"""


def toml_value(value) -> str:
    """A value in TOML syntax: JSON writes booleans, numbers, strings and lists as TOML does."""
    return json.dumps(list(value) if isinstance(value, tuple) else value)


def table_section(name: str, table) -> list[str]:
    """One table: its class's summary, then a row per key."""
    summary = " ".join(inspect.getdoc(type(table)).split("\n\n")[0].split())
    lines = [f"## [{name}]", "", summary, "", "| key | default | reference | meaning |", "|---|---|---|---|"]
    for key, value, meaning, reference in describe(table):
        shown = f"`{reference}`" if reference else ""
        meaning = meaning.replace("|", r"\|")
        lines.append(f"| `{key}` | `{toml_value(value)}` | {shown} | {meaning} |")
    return [*lines, ""]


def reference_toml() -> str:
    """The TOML that turns the defaults into the reference's workflow."""
    lines = []
    for name, values in REFERENCE_WORKFLOW.items():
        lines.append(f"[{name}]")
        lines.extend(f"{key} = {toml_value(value)}" for key, value in values.items())
    return "\n".join(lines)


def markdown() -> str:
    """The whole of docs/CONFIGURATION.md."""
    config = Config()
    lines = [INTRO]
    for name in STAGE_TABLES:
        lines.extend(table_section(name, getattr(config, name)))
    lines.extend([REFERENCE_INTRO, "```toml", reference_toml(), "```", ""])
    return "\n".join(lines)


if __name__ == "__main__":
    DOC.parent.mkdir(exist_ok=True)
    DOC.write_text(markdown(), encoding="utf-8")
    print(f"wrote {DOC}")
