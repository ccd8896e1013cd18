"""The project's JupyterLab settings (jupyter/, on JUPYTER_CONFIG_PATH in make lab and the README): the
notebooks open without a build prompt, conftest.py out of their folder, the kernels' variables set."""

import os
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SETTINGS = ROOT / "jupyter"


def test_jupyterlab_does_not_ask_for_a_build(monkeypatch):
    config = pytest.importorskip("jupyterlab_server.config")
    monkeypatch.setenv("JUPYTER_CONFIG_PATH", str(SETTINGS))
    assert config.get_static_page_config(level="all")["buildCheck"] is False


def test_the_notebooks_folder_lists_no_conftest_and_the_kernels_get_the_variables(monkeypatch):
    pytest.importorskip("jupyter_server")
    from jupyter_server.services.contents.filemanager import FileContentsManager
    from traitlets.config.loader import PyFileConfigLoader

    monkeypatch.setattr("os.environ", {"OMP_WAIT_POLICY": "active"})  # a user's own value is kept
    settings = PyFileConfigLoader("jupyter_server_config.py", path=str(SETTINGS)).load_config()
    assert os.environ == {"OMP_WAIT_POLICY": "active", "OPEN3D_DISABLE_WEB_VISUALIZER": "true"}
    listing = FileContentsManager(root_dir=str(ROOT / "notebooks"), config=settings).get("", content=True)
    names = {entry["name"] for entry in listing["content"]}
    assert (ROOT / "notebooks" / "conftest.py").exists() and "conftest.py" not in names
    assert "01_dataset.ipynb" in names and "__pycache__" not in names


def test_make_lab_and_the_readme_start_jupyterlab_with_these_settings():
    make = (ROOT / "Makefile").read_text()
    assert "JUPYTER_CONFIG_PATH=$(CURDIR)/jupyter $(VENV)/bin/jupyter lab" in make
    assert '$$([ "$$(id -u)" = 0 ] && echo --allow-root)' in make  # JupyterLab refuses root without it
    readme = (ROOT / "README.md").read_text()
    assert "JUPYTER_CONFIG_PATH=$PWD/jupyter .venv/bin/jupyter lab notebooks/" in readme
    assert "--allow-root" in readme.split("## Learning in JupyterLab")[1].split("\n## ")[0]
