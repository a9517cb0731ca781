"""The HTML report and out/index.html as a person sees them (issue 17): opened in headless
Chromium (Debian's chromium, installed by bootstrap), the page renders with its plots (SVG
images that parse, and that Chromium draws: a check figure alone, screenshotted, has its
trace's colour where the trace is) and logs nothing to the console."""
from __future__ import annotations

import base64
import re
import shutil
import subprocess
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest

from hil.cli.main import main as hil_main
from hil.reports.svg import polyline_points

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
    return [base64.b64decode(m) for m in re.findall(r'src="data:image/svg\+xml;base64,([^"]+)"', dom)]


def screenshot(page: Path, png: Path, profile_dir: Path, size: str = "720,288") -> np.ndarray:
    """The page as Chromium draws it, RGB rows (PNG read by matplotlib's reader)."""
    subprocess.run([CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--no-first-run",
                    f"--user-data-dir={profile_dir}", "--hide-scrollbars",
                    f"--window-size={size}", f"--screenshot={png}", page.resolve().as_uri()],
                   capture_output=True, text=True, timeout=120, check=True)
    from matplotlib.image import imread

    return imread(str(png))[:, :, :3]


@pytest.fixture(scope="module")
def reports(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("out")
    assert hil_main(["run", str(PLAN), "--out", str(out), "--no-progress"]) == 0
    return out


def test_plan_report_renders_with_its_plots_and_no_console_messages(reports, tmp_path):
    page = sorted(reports.glob("**/report.html"))[0]
    dom, console = render(page, tmp_path / "chrome")
    assert "speed-step-sensored" in dom
    svgs = images(dom)
    assert len(svgs) >= 2 and all(ET.fromstring(s).tag.endswith("svg") and len(s) > 2000 for s in svgs)
    assert console == []


def first_trace_alone(svg: str) -> str:
    """The figure with only its first trace's polyline, in the colour cycle's first colour
    (the others may cover it where they agree; the plant's traces are drawn last)."""
    first = re.search(r'<polyline [^>]*stroke="#1f77b4"[^>]*/>', svg).group(0)
    return re.sub(r'<polyline [^>]*/>', "", svg).replace("</g>", first + "</g>", 1)


def drawn_fraction(svg: str, points: list[tuple[float, float]], work: Path) -> float:
    """The share of `points` (every 10th) on which Chromium's drawing of `svg` has the first
    trace's colour (#1f77b4, blue well above red even where anti-aliasing blends it with the
    white ground) within 2 px."""
    (work / "figure.svg").write_text(svg)
    rgb = screenshot(work / "figure.svg", work / "figure.png", work / "chrome")
    blue = rgb[:, :, 2] - rgb[:, :, 0] > 0.25
    sampled = points[::10]
    hits = sum(1 for x, y in sampled
               if blue[max(round(y) - 2, 0):round(y) + 3, max(round(x) - 2, 0):round(x) + 3].any())
    return hits / len(sampled)


def test_chromium_draws_the_check_figures_trace_where_its_points_are(reports, tmp_path):
    page = sorted(reports.glob("**/report.html"))[0]
    svg = first_trace_alone(images(page.read_text())[0].decode())
    points = polyline_points(svg)[0]
    assert len(points) > 100 and drawn_fraction(svg, points, tmp_path) > 0.9


def test_a_figure_whose_trace_is_not_where_its_points_say_is_seen(reports, tmp_path):
    """The drawing check can fail: the trace drawn 40 px lower than the points compared."""
    page = sorted(reports.glob("**/report.html"))[0]
    svg = first_trace_alone(images(page.read_text())[0].decode())
    points = polyline_points(svg)[0]
    text = re.search(r'<polyline points="([^"]*)"', svg).group(1)
    lowered = " ".join(f"{x:.1f},{y + 40:.1f}" for x, y in points)
    assert drawn_fraction(svg.replace(text, lowered), points, tmp_path) < 0.5


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
