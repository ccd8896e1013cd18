"""The README's configuration table and its layout say what the code says."""

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


def test_the_layout_names_every_module_of_the_package():
    """Each module of ``helpers/`` (its subpackages named as folders) appears in the README's layout, and
    every ``.py`` name the layout gives under ``helpers/`` is a module there."""
    layout = re.search(r"## Layout\n\n```\n(helpers/.*?)\n(?:notebooks/)", README.read_text(), re.S)
    assert layout, "the README has no layout block starting at helpers/"
    named = set(re.findall(r"\b(\w+\.py)\b", layout.group(1)))
    package = README.parent / "helpers"
    modules = {path.name for path in package.glob("*.py")} - {"__init__.py"}
    folders = {path.name for path in package.iterdir() if (path / "__init__.py").exists()}
    assert modules <= named, f"modules the layout leaves out: {sorted(modules - named)}"
    assert named - {"figures.py", "plots.py"} <= modules, f"the layout names no such module: {sorted(named - modules)}"
    assert {f"{folder}/" for folder in folders} <= set(re.findall(r"^  (\w+/)", layout.group(1), re.M))
