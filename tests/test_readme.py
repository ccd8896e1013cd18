"""The README and docs/ say what the code says: the configuration reference is generated from it, the
reference workflow's TOML is the one ``Config.reference()`` applies, and every relative link leads to a file."""

import re
import tomllib
from pathlib import Path

from helpers.config import reference_doc
from helpers.config.tables import REFERENCE_WORKFLOW, Config

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
CONFIGURATION = ROOT / "docs" / "CONFIGURATION.md"
MAX_README_LINES = 300


def test_the_configuration_reference_is_generated_from_the_code():
    assert CONFIGURATION.read_text(encoding="utf-8") == reference_doc.markdown(), (
        "docs/CONFIGURATION.md differs from the configuration's help text: run python -m helpers.config.reference_doc"
    )


def test_the_reference_config_file_is_the_reference_workflow():
    """The TOML block under "The reference's workflow" holds exactly what ``Config.reference()`` changes."""
    block = re.search(r"## The reference's workflow\n.*?```toml\n(.*?)```", CONFIGURATION.read_text(), re.S)
    assert block, "docs/CONFIGURATION.md shows no TOML block for the reference's workflow"
    assert tomllib.loads(block.group(1)) == REFERENCE_WORKFLOW
    assert Config.reference() == Config().with_values(**REFERENCE_WORKFLOW)


def test_the_readme_is_a_guide():
    lines = README.read_text().splitlines()
    assert len(lines) <= MAX_README_LINES, f"README.md has {len(lines)} lines; move detail to docs/"


def relative_links(page: Path) -> list[str]:
    """The targets of a page's Markdown links and images that are not web addresses or in-page anchors."""
    text = re.sub(r"```.*?```", "", page.read_text(), flags=re.S)  # code holds no links
    text = re.sub(r"`[^`\n]*`", "", text)
    targets = re.findall(r"\]\(([^)\s]+)\)", text)
    return [target for target in targets if not re.match(r"[a-z][a-z0-9+.-]*:|#", target)]


def test_every_relative_link_leads_to_a_file():
    pages = [README, *sorted((ROOT / "docs").glob("*.md"))]
    broken = [
        f"{page.relative_to(ROOT)}: {target}"
        for page in pages
        for target in relative_links(page)
        if not (page.parent / target.split("#")[0]).exists()
    ]
    assert not broken, f"links to no file: {broken}"
