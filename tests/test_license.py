"""The LICENSE file is the license pyproject.toml declares."""

from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_the_license_is_the_one_pyproject_declares():
    assert 'license = "BSD-3-Clause"' in (ROOT / "pyproject.toml").read_text()
    text = (ROOT / "LICENSE").read_text()
    assert text.startswith("BSD 3-Clause License\n\nCopyright (c) 2026, The aerial-lidar-slam-helpers authors\n")
    assert "Neither the name of the copyright holder nor the names of its" in text
