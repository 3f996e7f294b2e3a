"""A notebook's embedded Rerun viewer renders in a browser, offline: JupyterLab on 127.0.0.1
with a token, headless Chromium runs a notebook cell ``radarviz.show("velocity")``, the
widget loads its JavaScript and WebAssembly from the kernel's local asset server (the
installed rerun-notebook package), and the viewer's canvas shows coloured data."""

from __future__ import annotations

import os
import secrets
import signal
import subprocess
import sys
import time
import urllib.request
from pathlib import Path
from typing import Any

import nbformat

from radarviz.viz_app.rerun.viewer import free_port

ROOT = Path(__file__).resolve().parents[1]
ARTIFACTS = ROOT / "test-artifacts"


def _answers(url: str) -> bool:
    try:
        with urllib.request.urlopen(url, timeout=2) as r:
            return r.status == 200
    except OSError:
        return False


def _lab(folder: Path, port: int, token: str) -> subprocess.Popen:
    env = dict(os.environ)
    env.pop("RERUN_NOTEBOOK_ASSET", None)  # radarviz.show chooses the package's own assets
    # A private Jupyter configuration and runtime: no user settings, no workspace restored.
    for var, sub in (
        ("JUPYTER_CONFIG_DIR", "config"),
        ("JUPYTER_RUNTIME_DIR", "runtime"),
        ("JUPYTERLAB_WORKSPACES_DIR", "workspaces"),
        ("IPYTHONDIR", "ipython"),
    ):
        (folder / sub).mkdir()
        env[var] = str(folder / sub)
    return subprocess.Popen(
        [
            sys.executable,
            "-m",
            "jupyterlab",
            "--no-browser",
            "--allow-root",  # CI's containers run as root
            "--ServerApp.ip=127.0.0.1",
            f"--ServerApp.port={port}",
            "--ServerApp.port_retries=0",
            f"--IdentityProvider.token={token}",
            f"--ServerApp.root_dir={folder / 'nb'}",
            "--LabApp.news_url=",
            "--LabApp.extension_manager=readonly",
            "--LabApp.check_for_updates_class=jupyterlab.NeverCheckForUpdate",
        ],
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=open(folder / "lab.log", "w"),
        start_new_session=True,
    )


class _Region:
    """A page screenshot clipped to an element's box (the viewer's canvas keeps redrawing, so
    an element screenshot waiting for it to be stable would wait forever)."""

    def __init__(self, page: Any, element: Any) -> None:
        self.page, self.element = page, element

    def screenshot(self, path: str | None = None) -> bytes:
        box = self.element.bounding_box()
        assert box is not None and box["width"] > 100 and box["height"] > 100, box
        return self.page.screenshot(path=path, clip=box, timeout=120_000)


def _run_all(page: Any, attempts: int = 3) -> None:
    """Run > Run All Cells until the cell shows it ran or runs ("[1]" or "[*]"): a request
    sent while the kernel connection still settles can be dropped."""
    prompt = page.locator(".jp-Cell .jp-InputPrompt").first
    for _ in range(attempts):
        page.locator(".lm-MenuBar-itemLabel").get_by_text("Run", exact=True).click()
        page.locator("li[data-command='runmenu:run-all']").click()
        end = time.monotonic() + 30
        while time.monotonic() < end:
            if any(mark in prompt.inner_text() for mark in ("[*]", "[1]")):
                return
            time.sleep(0.5)
    raise AssertionError(f"the cell did not run after {attempts} attempts: {prompt.inner_text()}")


def test_notebook_viewer_renders(
    tmp_path: Path, chromium: tuple[str, list[str]], viewer_shows_data
) -> None:
    from playwright.sync_api import sync_playwright

    (tmp_path / "nb").mkdir()
    nb = nbformat.v4.new_notebook()
    nb.metadata["kernelspec"] = {"name": "python3", "display_name": "Python 3"}
    nb.cells.append(
        nbformat.v4.new_code_cell('import radarviz\nradarviz.show("velocity", height=600)')
    )
    nbformat.write(nb, tmp_path / "nb" / "viewer.ipynb")
    port, token = free_port(), secrets.token_hex(16)
    proc = _lab(tmp_path, port, token)
    try:
        end = time.monotonic() + 120
        while not _answers(f"http://127.0.0.1:{port}/api/status?token={token}"):
            assert proc.poll() is None, (tmp_path / "lab.log").read_text()[-3000:]
            assert time.monotonic() < end, "JupyterLab did not answer in 120 s"
            time.sleep(0.5)
        executable, args = chromium
        with sync_playwright() as p:
            browser = p.chromium.launch(executable_path=executable, args=args)
            page = browser.new_page(viewport={"width": 1400, "height": 1000})
            page.goto(f"http://127.0.0.1:{port}/lab/tree/viewer.ipynb?token={token}")
            page.get_by_text("Python 3 (ipykernel) | Idle").wait_for(timeout=180_000)
            _run_all(page)
            canvas = page.locator(".jp-OutputArea-output canvas").first
            try:
                canvas.wait_for(state="visible", timeout=180_000)
            except Exception:
                ARTIFACTS.mkdir(exist_ok=True)
                page.screenshot(path=str(ARTIFACTS / "notebook_viewer_failed.png"), timeout=120_000)
                log = (tmp_path / "lab.log").read_text()[-3000:]
                raise AssertionError(
                    f"no viewer canvas (see notebook_viewer_failed.png)\n{log}"
                ) from None
            errors = page.locator(".jp-OutputArea-output[data-mime-type*='stderr']")
            fraction = viewer_shows_data(
                _Region(page, canvas), ARTIFACTS / "notebook_viewer.png", timeout=120
            )
            assert fraction > 0.002
            text = page.locator(".jp-OutputArea").first.inner_text()
            assert "Serving rerun notebook assets at http://127.0.0.1" in text, text[:2000]
            assert errors.count() == 0 or "Traceback" not in errors.first.inner_text()
            browser.close()
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGTERM)
            proc.wait(timeout=20)
