"""The plan reports and the sweep page as a new user reads them in a browser (issue "a user's
first hour", part 7): real runs of plans 01 and 02 (in-process stub, paper profile) and a
three-run sweep, each page loaded in headless Chromium (tests/test_report_browser.py's
driver) with a probe script that puts every figure into the page's own document, lets the
browser lay it out, and writes what it drew as JSON: each figure's legend entries with their
colours and drawn widths, its axis label, its tick labels per axis, the order of its traces
and whether a limit line exists. The page's structure (verdicts before the folded
description) is read from the same DOM; one screenshot of a report is checked not blank."""
from __future__ import annotations

import json
import re
import textwrap
from pathlib import Path

import numpy as np
import pytest

from hil.cli.main import main as hil_main
from tests.test_report_browser import CHROMIUM, render, screenshot

pytestmark = pytest.mark.skipif(CHROMIUM is None, reason="needs Debian's chromium (bootstrap installs it)")
REPO = Path(__file__).resolve().parents[1]
PLANS = {"01": REPO / "test_plans" / "01_speed_step_sensored.yaml",
         "02": REPO / "test_plans" / "02_steady_state_3000rpm.yaml"}
RED = "#cf222e"

#: Runs in the loaded page: every SVG figure (the reports' <img> data URIs, the sweep page's
#: inline <svg>) parsed by the browser, placed in the document (clip ids made unique), laid out,
#: and described in <pre id="probe">.
PROBE = r"""<script>
addEventListener("load", () => {
  const box = document.createElement("div");
  document.body.appendChild(box);
  const figures = [];
  const svgs = [];
  document.querySelectorAll('img[src^="data:image/svg+xml;base64,"]').forEach((img, i) => {
    const text = new TextDecoder().decode(Uint8Array.from(atob(img.src.split(",")[1]), c => c.charCodeAt(0)));
    const doc = new DOMParser().parseFromString(text.replaceAll("clip", "f" + i + "clip"), "image/svg+xml");
    svgs.push([img.alt, box.appendChild(document.importNode(doc.documentElement, true))]);
  });
  document.querySelectorAll("div.fig > svg").forEach(svg => svgs.push(["sweep", svg]));
  for (const [alt, svg] of svgs) {
    const texts = [...svg.querySelectorAll("text")];
    const sized = size => texts.filter(t => t.getAttribute("font-size") === size);
    const group = attr => {
      const g = {};
      sized("10").forEach(t => (g[t.getAttribute(attr)] ??= []).push(t.textContent));
      return Object.values(g).filter(v => v.length > 1);
    };
    figures.push({
      alt,
      legend: sized("9").filter(t => !t.getAttribute("transform")).map(t => {
        const mark = t.previousElementSibling;
        return {text: t.textContent, width: t.getComputedTextLength(),
                color: mark.getAttribute("stroke") || mark.getAttribute("fill")};
      }),
      ylabel: sized("11").filter(t => (t.getAttribute("transform") || "").includes("rotate")).map(t => t.textContent),
      texts: texts.map(t => t.textContent),
      ticks: group("x").concat(group("y")),
      traces: [...svg.querySelectorAll("polyline")].map(p => p.getAttribute("stroke")),
      red_lines: [...svg.querySelectorAll("path")].filter(p => p.getAttribute("stroke") === "#cf222e").length,
    });
  }
  const pre = document.createElement("pre");
  pre.id = "probe";
  pre.textContent = JSON.stringify(figures);
  document.body.appendChild(pre);
});
</script>"""


def probed(page: Path, work: Path) -> tuple[str, dict[str, dict]]:
    """The DOM Chromium built from `page` and the figures it drew, by alt text."""
    copy = work / f"probed-{page.parent.name}.html"
    copy.write_text(page.read_text().replace("</body>", PROBE + "</body>"))
    dom, console = render(copy, work / "chrome")
    assert console == []
    found = re.search(r'<pre id="probe">(.*?)</pre>', dom, re.S)
    assert found, "the probe did not run"
    figures = json.loads(found.group(1).replace("&amp;", "&").replace("&lt;", "<").replace("&gt;", ">"))
    assert figures, "no figures"
    return dom, {f["alt"]: f for f in figures}


@pytest.fixture(scope="module")
def out(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("runs")
    assert hil_main(["run", str(PLANS["01"]), str(PLANS["02"]), "--profile", "paper",
                     "--out", str(path), "--no-progress"]) == 0
    return path


@pytest.fixture(scope="module")
def report01(out, tmp_path_factory):
    return probed(next(out.glob("speed-step-sensored/**/report.html")), tmp_path_factory.mktemp("p01"))


@pytest.fixture(scope="module")
def report02(out, tmp_path_factory):
    return probed(next(out.glob("steady-state-3000rpm/**/report.html")), tmp_path_factory.mktemp("p02"))


SWEEP_PLAN = """\
name: sweep-report
description: 0.4 s at 1500 rpm; its checks measure nearly the same value in every run.
steps:
  - command: {enable: true, speed_source: encoder, speed_ref_rpm: 1500}
  - run: {duration_s: 0.4}
  - check:
      name: mean speed
      kind: statistic
      statistic: mean
      signal: plant.speed_rpm
      window: {from: start, offset_s: 0.3, duration_s: 0.1}
      limits: {low: 0, high: 3000, unit: rpm}
  - check:
      name: board state
      kind: statistic
      statistic: max
      signal: ctrl.state
      limits: {low: 0, high: 10, unit: "1"}
"""


@pytest.fixture(scope="module")
def sweep_page(tmp_path_factory):
    """Three runs whose inertia differs by 2.5 ppm: the measured speeds (about 1500.3 ..
    1500.5 rpm) and the inertias (0.0008 ...) both span far less than their magnitudes."""
    work = tmp_path_factory.mktemp("sweep")
    (work / "plan.yaml").write_text(SWEEP_PLAN)
    (work / "tiny.sweep.yaml").write_text(textwrap.dedent(f"""\
        sweep:
          name: tiny
          plans: [{work / 'plan.yaml'}]
          seed: 4
          sampling: monte_carlo
          runs: 3
          parameters:
            profile.motor.inertia_kgm2: {{uniform: {{low: 8.0e-4, high: 8.00002e-4}}}}
        """))
    assert hil_main(["sweep", str(work / "tiny.sweep.yaml"), "--out", str(work / "out")]) == 0
    return probed(work / "out" / "index.html", work)


# ----------------------------------------------------------------------------- the plan reports

def test_verdicts_come_before_the_description_which_is_folded(report02):
    dom, _ = report02
    verdicts = dom.index("<h2>Verdicts</h2>")
    first_table = dom.index("flux magnitude ripple inside the hysteresis band", verdicts)
    derivation = dom.index("Flux band 2/3 Vdc T")            # a line of plan 02's description
    assert verdicts < first_table < derivation
    details = dom.rindex("<details", 0, derivation)
    assert dom.index("</details>", details) > derivation      # folded into a <details>
    assert "open" not in dom[details:dom.index(">", details)]
    assert dom.index("Plan description") > first_table


NAME_SUFFIX_UNITS = {"_rpm": "rpm", "_rad_s": "rad/s", "_nm": "Nm", "_wb": "Wb"}


def unit_of(label: str) -> str | None:
    """The unit a legend entry names: in brackets at its end, else its name's suffix (the
    signal catalogue's naming: plant.speed_rpm, ctrl.speed_feedback_rad_s)."""
    said = re.search(r"\(([^()]+)\)$", label)
    if said:
        return said.group(1)
    return next((u for suffix, u in NAME_SUFFIX_UNITS.items() if label.endswith(suffix)), None)


def trace_entries(figure: dict) -> list[dict]:
    return [e for e in figure["legend"] if re.match(r"(plant|ctrl|cmd)\.", e["text"])]


@pytest.mark.parametrize("report", ["report01", "report02"])
def test_legend_units_agree_with_the_axis(report, request):
    _, figures = request.getfixturevalue(report)
    seen = 0
    for alt, figure in figures.items():
        if len(figure["ylabel"]) != 1 or "(" in figure["ylabel"][0]:
            continue                                     # xy figures name each axis
        for entry in trace_entries(figure):
            assert entry["width"] > 0, (alt, entry)      # drawn
            assert unit_of(entry["text"]) in (None, figure["ylabel"][0]), (alt, entry["text"])
            seen += 1
    assert seen > 5
    if report == "report01":     # its speed plot asks for ctrl.speed_feedback_rad_s in rpm
        assert [e["text"] for e in trace_entries(figures["Speed (Fig. 4a / 6a)"])] == [
            "plant.speed_rpm", "cmd.speed_ref_rpm", "ctrl.speed_feedback (rpm)"]


def test_the_plants_traces_are_drawn_above_the_estimates(report01, report02):
    checked = 0
    for figures in (report01[1], report02[1]):
        for alt in ("Flux magnitude", "Torque", "Speed (Fig. 4a / 6a)", "Electromagnetic torque (Fig. 4b / 6b)"):
            if alt not in figures:
                continue
            entries = trace_entries(figures[alt])
            truth = {e["color"] for e in entries if e["text"].startswith("plant.")}
            others = {e["color"] for e in entries} - truth
            order = figures[alt]["traces"]
            assert truth and others
            assert max(i for i, c in enumerate(order) if c in truth) > \
                max(i for i, c in enumerate(order) if c in others), alt
            checked += 1
    assert checked == 4


def statistic_names(figure: dict) -> list[str]:
    return [e["text"] for e in figure["legend"] if not re.match(r"(plant|ctrl|cmd)\.|window$", e["text"])]


def test_statistic_checks_draw_no_limit_lines_and_name_their_statistic(report02):
    _, figures = report02
    expected = {"flux magnitude at its reference": "mean = ",
                "mean torque equals load plus damping": "mean = ",
                "phase current RMS": "\u00b1RMS = ",
                "torque ripple peak-to-peak": "peak-to-peak = ",
                "torque ripple RMS": "mean \u00b1 RMS ripple",
                "flux magnitude ripple inside the hysteresis band": "peak-to-peak = "}
    for alt, name in expected.items():
        figure = figures[alt]
        assert figure["red_lines"] == 0, alt
        labels = statistic_names(figure)
        assert labels and all(label.startswith(name) for label in labels), (alt, labels)
        assert not any("limit" in label or "p-p" in label for label in labels), (alt, labels)


def test_checks_on_the_signal_itself_still_draw_their_limits(report01):
    _, figures = report01
    for alt in ("final speed", "torque within the limit"):
        assert figures[alt]["red_lines"] >= 1 and "limit" in statistic_names(figures[alt]), alt


@pytest.mark.parametrize("page", ["report01", "report02", "sweep_page"])
def test_no_axis_has_two_tick_labels_alike(page, request):
    _, figures = request.getfixturevalue(page)
    axes = [ticks for figure in figures.values() for ticks in figure["ticks"]]
    assert len(axes) >= 2
    for ticks in axes:
        assert len(set(ticks)) == len(ticks), ticks


# ----------------------------------------------------------------------------- the sweep page

def test_sweep_units_are_printed_sanely(sweep_page):
    dom, figures = sweep_page
    row = re.search(r"<td>board state</td>(.*?)</tr>", dom).group(1)
    spread = re.search(r"<td>([^<]* / [^<]* / [^<]*)</td>", row).group(1)
    assert re.fullmatch(r"-?[\d.]+ / -?[\d.]+ / -?[\d.]+", spread), spread     # no unit "1"
    speed = re.search(r"<td>mean speed</td>(.*?)</tr>", dom).group(1)
    assert re.search(r"<td>[\d.]+ / [\d.]+ / [\d.]+ rpm</td>", speed)
    lo, mid, hi = (float(v) for v in re.search(r"<td>([\d.]+) / ([\d.]+) / ([\d.]+) rpm", speed).groups())
    assert lo < hi                                  # the spread shows: not 1500 / 1500 / 1500
    titles = [t for f in figures.values() for t in f["texts"] if t.startswith(("mean speed", "board state"))]
    assert titles and all(not t.endswith("[1]") for t in titles)


# ----------------------------------------------------------------------------- a screenshot

def test_a_report_screenshot_is_not_blank(out, tmp_path):
    rgb = screenshot(next(out.glob("steady-state-3000rpm/**/report.html")), tmp_path / "page.png",
                     tmp_path / "chrome", size="1000,900")
    ink = np.any(rgb < 0.9, axis=2)
    green = (rgb[:, :, 1] - rgb[:, :, 0] > 0.2) & (rgb[:, :, 1] - rgb[:, :, 2] > 0.1)   # PASS badge
    assert rgb.shape[:2] == (900, 1000) and 0.005 < ink.mean() < 0.6 and green.any()
