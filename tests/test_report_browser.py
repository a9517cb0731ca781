"""The HTML report and out/index.html as a person sees them (issue 17): opened in headless
Chromium (Debian's chromium, installed by bootstrap), the page renders with its plots (PNG
images that decode) and logs nothing to the console."""
from __future__ import annotations

import base64
import re
import shutil
import subprocess
from pathlib import Path

import pytest

from hil.cli.main import main as hil_main

CHROMIUM = shutil.which("chromium")
pytestmark = pytest.mark.skipif(CHROMIUM is None, reason="needs Debian's chromium (bootstrap installs it)")
PLAN = Path(__file__).resolve().parents[1] / "test_plans" / "01_speed_step_sensored.yaml"


def render(page: Path, profile_dir: Path) -> tuple[str, list[str]]:
    """The DOM after loading `page`, and the console messages it logged."""
    proc = subprocess.run([CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
                           "--no-first-run", "--disable-background-networking",
                           "--disable-component-update", "--disable-sync",
                           f"--user-data-dir={profile_dir}", "--enable-logging=stderr", "--v=0",
                           "--dump-dom", page.resolve().as_uri()],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr[-2000:]
    console = [line for line in proc.stderr.splitlines() if ":CONSOLE" in line]
    return proc.stdout, console


def images(dom: str) -> list[bytes]:
    return [base64.b64decode(m) for m in re.findall(r'src="data:image/png;base64,([^"]+)"', dom)]


@pytest.fixture(scope="module")
def reports(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("out")
    assert hil_main(["run", str(PLAN), "--out", str(out), "--no-progress"]) == 0
    return out


def test_plan_report_renders_with_its_plots_and_no_console_messages(reports, tmp_path):
    page = next(reports.glob("*/report.html"))
    dom, console = render(page, tmp_path / "chrome")
    assert "speed-step-sensored" in dom
    pngs = images(dom)
    assert len(pngs) >= 2 and all(p.startswith(b"\x89PNG\r\n\x1a\n") and len(p) > 2000 for p in pngs)
    assert console == []


def test_index_renders_and_links_every_plan(reports, tmp_path):
    dom, console = render(reports / "index.html", tmp_path / "chrome")
    assert "speed-step-sensored" in dom and "report.html" in dom
    assert console == []


def test_a_console_error_is_seen(tmp_path):
    """The console check can fail: a page that logs an error is reported."""
    page = tmp_path / "bad.html"
    page.write_text('<html><body><script>console.error("boom")</script></body></html>')
    _, console = render(page, tmp_path / "chrome")
    assert any('"boom"' in line for line in console)
