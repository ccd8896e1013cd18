"""The README's configuration table says what the code says."""

import re
import tomllib
from pathlib import Path

from helpers.config import REFERENCE_WORKFLOW, STAGE_TABLES, Config, describe

README = Path(__file__).resolve().parents[1] / "README.md"


def readme_rows() -> dict[tuple[str, str], tuple[str, str]]:
    """(table, key) -> (default, reference) as the README's configuration table lists them."""
    rows, table = {}, None
    for line in README.read_text().splitlines():
        if heading := re.fullmatch(r"\| \*\*\[(\w+)\]\*\* \|.*", line):
            table = heading.group(1)
        elif table and (row := re.fullmatch(r"\| `(\w+)` \| (.*?) \| (.*?) \| .* \|", line)):
            rows[table, row.group(1)] = (row.group(2), row.group(3).strip("`"))
        elif table and not line.startswith("|"):
            table = None
    return rows


def test_the_configuration_table_lists_every_parameter_with_its_default():
    expected = {}
    for table in STAGE_TABLES:
        for name, value, _, reference in describe(getattr(Config(), table)):
            default = list(value) if isinstance(value, tuple) else value
            shown = f'"{default}"' if isinstance(default, str) else str(default)
            expected[table, name] = (shown, reference or "")
    assert readme_rows() == expected


def test_the_reference_config_file_is_the_reference_workflow():
    """The README's TOML for the reference's workflow holds exactly what ``Config.reference()`` changes."""
    block = re.search(r"is one\s+config away.*?```toml\n(.*?)```", README.read_text(), re.S)
    assert block, "the README shows no TOML block"
    assert tomllib.loads(block.group(1)) == REFERENCE_WORKFLOW
    assert Config.reference() == Config().with_values(**REFERENCE_WORKFLOW)
