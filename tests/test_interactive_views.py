"""The interactive 3-D views, as a learner meets them: JupyterLab started
headless, a notebook calling :func:`helpers.viz.render.explore` opened in
headless Chromium and run, then PyVista's trame view must appear in the
output (served from this machine), draw the cloud, and turn when dragged
with the mouse. Skipped without Chromium, like the book's browser tests."""

import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from browser import CHROMIUM, Browser
from PIL import Image

ROOT = Path(__file__).resolve().parents[1]
TOKEN = "interactive-views-test"
CELL = """\
import numpy as np
from helpers.viz import render
from helpers.viz.display import interactive_views

rng = np.random.default_rng(0)
xy = rng.uniform(0, 100, (20000, 2))
print("interactive:", interactive_views())
render.explore(np.c_[xy, 5 * np.sin(xy[:, 0] / 10) + xy[:, 1] / 10])"""
PANEL = "(window.jupyterapp && Array.from(jupyterapp.shell.widgets('main')).find(w => w.sessionContext))"
IFRAME_BOX = """(() => {
  const frame = document.querySelector('.jp-OutputArea iframe');
  if (!frame) return null;
  frame.scrollIntoView({block: 'center'});
  const r = frame.getBoundingClientRect();
  return {src: frame.src, x: r.left + scrollX, y: r.top + scrollY, width: r.width, height: r.height};
})()"""
DISMISS = """document.querySelectorAll('.jp-Dialog-button.jp-mod-reject, .jp-toast-dismiss')
  .forEach(button => button.click()); true"""  # e.g. "build recommended" for an extension the venv happens to have


def _free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def _poll(check, timeout: float, every: float = 1.0):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        value = check()
        if value is not None and value is not False:
            return value
        time.sleep(every)
    return None


def _pixels(path: Path) -> np.ndarray:
    return np.asarray(Image.open(path).convert("RGB"), dtype=float)


def _coloured_share(pixels: np.ndarray) -> float:
    """Share of pixels in colour: the cloud's points (an empty view is white or grey)."""
    return float(np.mean(pixels.max(axis=2) - pixels.min(axis=2) > 30))


@pytest.fixture()
def lab(tmp_path):
    """JupyterLab on a free local port, its settings, workspaces and runtime files in ``tmp_path``."""
    if not CHROMIUM.exists():
        pytest.skip(f"no browser at {CHROMIUM}: this check needs Debian's chromium (make test installs it as root)")
    import nbformat.v4

    notebook = nbformat.v4.new_notebook(cells=[nbformat.v4.new_code_cell(CELL)])
    notebook.metadata["kernelspec"] = {"name": "python3", "display_name": "Python 3", "language": "python"}
    nbformat.write(notebook, tmp_path / "view.ipynb")
    port = _free_port()
    environment = {
        **os.environ,
        "PYTHONPATH": os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")])),
        "OPEN3D_DISABLE_WEB_VISUALIZER": "true",
        "JUPYTER_RUNTIME_DIR": str(tmp_path / "runtime"),
    }
    environment.pop("HELPERS_3D", None)  # the learner's default: interactive where it can be
    log = (tmp_path / "lab.log").open("w")
    server = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "jupyterlab",
            "--no-browser",
            "--allow-root",
            "--ip=127.0.0.1",
            f"--port={port}",
            f"--ServerApp.token={TOKEN}",
            f"--ServerApp.root_dir={tmp_path}",
            "--LabApp.expose_app_in_browser=True",  # window.jupyterapp: run the cells by command
            f"--LabApp.workspaces_dir={tmp_path / 'workspaces'}",
            f"--LabApp.user_settings_dir={tmp_path / 'settings'}",
            "--LabApp.news_url=",
        ],
        cwd=tmp_path,
        env=environment,
        stdout=log,
        stderr=subprocess.STDOUT,
        start_new_session=True,  # its kernels too, stopped together below
    )
    try:

        def up():
            try:
                with socket.create_connection(("127.0.0.1", port), timeout=1):
                    return True
            except OSError:
                return server.poll() is not None  # stop waiting if it died

        _poll(up, 120, 0.5)
        assert server.poll() is None, "JupyterLab did not start:\n" + (tmp_path / "lab.log").read_text()[-3000:]
        yield f"http://127.0.0.1:{port}/lab/tree/view.ipynb?token={TOKEN}"
    finally:
        os.killpg(server.pid, signal.SIGTERM)
        try:
            server.wait(timeout=30)
        except subprocess.TimeoutExpired:
            os.killpg(server.pid, signal.SIGKILL)
            server.wait()
        log.close()


def _drag(browser: Browser, x: float, y: float, dx: float, dy: float, steps: int = 20) -> None:
    """A left-button drag, as a hand turning the view."""
    mouse = lambda kind, px, py, buttons, **extra: browser.call(  # noqa: E731
        "Input.dispatchMouseEvent", session=True, type=kind, x=px, y=py, buttons=buttons, **extra
    )
    mouse("mouseMoved", x, y, 0)
    mouse("mousePressed", x, y, 1, button="left", clickCount=1)
    for step in range(1, steps + 1):
        mouse("mouseMoved", x + dx * step / steps, y + dy * step / steps, 1, button="left")
        time.sleep(0.05)
    mouse("mouseReleased", x + dx, y + dy, 0, button="left", clickCount=1)


def test_the_trame_view_appears_in_jupyterlab_and_turns(lab, tmp_path):
    with Browser(window=(1400, 1000)) as browser:
        browser.resize(1400, 1000)
        browser.open(lab, timeout=120)
        assert _poll(lambda: browser.evaluate(PANEL + " ? true : null"), 120), "JupyterLab did not show the notebook"
        browser.evaluate(f"{PANEL}.sessionContext.ready.then(() => true)", timeout=120)
        browser.evaluate(DISMISS)
        browser.evaluate(f"jupyterapp.shell.activateById({PANEL}.id); true")  # the commands act on the active one
        browser.evaluate("jupyterapp.commands.execute('notebook:run-all-cells'); true")  # the output is polled below
        box = _poll(lambda: browser.evaluate(IFRAME_BOX), 180)
        assert box, "no view in the cell's output"
        output = browser.evaluate("document.querySelector('.jp-OutputArea').innerText")
        assert "interactive: True" in output, f"the kernel would draw still pictures: {output[:300]}"
        assert box["src"].startswith(("http://localhost:", "http://127.0.0.1:")), f"the view comes from {box['src']}"
        clip = {key: box[key] for key in ("x", "y", "width", "height")}

        def drawn():  # the cloud is there once the view shows its colours
            browser.evaluate(DISMISS)
            pixels = _pixels(browser.screenshot(tmp_path / "before.png", clip))
            return pixels if _coloured_share(pixels) > 0.05 else None

        before = _poll(drawn, 120, 2)
        assert before is not None, f"the view stayed empty (see {tmp_path / 'before.png'})"

        centre_x, centre_y = box["x"] + box["width"] / 2, box["y"] + box["height"] / 2
        _drag(browser, centre_x - 100, centre_y, 250, 60)

        def turned():
            after = _pixels(browser.screenshot(tmp_path / "after.png", clip))
            return float(np.mean(np.abs(after - before).max(axis=2) > 30)) > 0.1 and _coloured_share(after) > 0.05

        assert _poll(turned, 60, 2), f"the view did not turn when dragged (see {tmp_path / 'after.png'})"
        local = ("http://127.0.0.1:", "http://localhost:", "ws://127.0.0.1:", "ws://localhost:", "data:", "blob:")
        leaving = [url for url in browser.requested() if not url.startswith((*local, "about:"))]
        assert not leaving, f"JupyterLab asked the network for {leaving}"
