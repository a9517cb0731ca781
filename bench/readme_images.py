"""The README's four pictures (docs/img/), made again from today's runs, and the figures their
captions quote.

- speed_step.png, flux_locus.png, ekf_speed.png: one entry of a plan's ``plots:`` section, as
  its report draws it (hil.reports.html.plan_figure, the SVG of report.html), from the run
  `make run` makes (`hil run test_plans/`: the plan's first profile, paper; stub in
  lockstep; seed 0). The SVG becomes a PNG in headless Chromium at the figure's own size.
- sweep_summary.png: headless Chromium's screenshot (1200 x 1500) of the index.html that
  `hil sweep test_plans/sweeps/sensorless_tolerances.yaml --workers 2` writes (32 runs, seed
  16; about 15 s on two cores, the whole module about 30 s, --quick 9 s).

`python -m bench readme_images` writes the four into docs/img/ and prints what the captions
quote: the speed step's commanded levels, the flux locus's speed, the sweep's runs, seed,
passed runs and the strongest parameter of each failed check (the page's "strongest parameter"
column). Without a Chromium no PNG is written: the old files stay and the output says so.
`--quick` writes nothing into docs/img/: it draws the three plan figures into a temporary
directory and leaves the sweep out (so `hil bench --quick` checks the path in seconds). A full
`hil bench` runs this module too (it runs every one) and so rewrites docs/img/: the runs are
seeded and lockstep, and two runs on one tree wrote byte-identical PNGs, so the files change
only when the plots do. No test runs it.
"""
from __future__ import annotations

import base64
import os
import shutil
import subprocess
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
IMG = ROOT / "docs" / "img"
PLANS = ROOT / "test_plans"
SWEEP = PLANS / "sweeps" / "sensorless_tolerances.yaml"
SWEEP_WORKERS = 2
SWEEP_WINDOW = (1200, 1500)        # the screenshot's size, as the first one (2e452cf)
BROWSERS = ("chromium", "chromium-browser", "google-chrome", "chromium-headless-shell")

# README picture -> (plan file, title of the entry in its plots: section)
FIGURES = {
    "speed_step.png": ("01_speed_step_sensored.yaml", "Speed (Fig. 4a / 6a)"),
    "flux_locus.png": ("02_steady_state_3000rpm.yaml", "Stator flux locus (Fig. 5b / 7b)"),
    "ekf_speed.png": ("03_speed_estimation.yaml", "EKF speed vs truth (Fig. 9c)"),
}


def browser() -> str | None:
    """The first Chromium on PATH, or None."""
    for name in BROWSERS:
        path = shutil.which(name)
        if path:
            return path
    return None


def screenshot(chrome: str, url: str, png: Path, width: int, height: int) -> None:
    """Headless Chromium's screenshot of `url` at width x height CSS pixels (device scale 1)."""
    with tempfile.TemporaryDirectory() as profile:
        argv = [chrome, "--headless", "--disable-gpu", "--hide-scrollbars", "--no-first-run",
                f"--user-data-dir={profile}", "--force-device-scale-factor=1",
                f"--window-size={width},{height}", f"--screenshot={png}", url]
        if hasattr(os, "geteuid") and os.geteuid() == 0:
            argv.insert(1, "--no-sandbox")     # Chromium refuses its sandbox as root
        subprocess.run(argv, check=True, capture_output=True, timeout=120)
    if not png.is_file() or png.stat().st_size == 0:
        raise RuntimeError(f"{chrome} wrote no screenshot {png}")


def _window(spec, result, signals) -> tuple[float, float]:
    """The plot's time window, as plan_figure resolves it."""
    end_s = signals.end_s if len(signals) else result.sim_duration_s
    if spec.window is None:
        return 0.0, end_s
    try:
        return spec.window.resolve(result.marks, end_s)
    except KeyError:
        return 0.0, end_s


def _levels(signal, a: float, b: float, unit: str) -> list[float]:
    """The distinct values a step signal takes in [a, b] (rounded to 0.1), in order."""
    out: list[float] = []
    for v in signal.window(a, b).to_unit(unit).values:
        v = round(float(v), 1)
        if not out or out[-1] != v:
            out.append(v)
    return out


def _mean(signal, a: float, b: float, unit: str) -> float:
    return float(signal.window(a, b).to_unit(unit).values.mean())


def plan_figures(out_dir: Path, chrome: str | None) -> dict:
    """Runs the three plans and writes the three PNGs (when there is a browser) into out_dir;
    returns per picture the plan's outcome and the figures its caption quotes."""
    from hil.plans.format import load_plan
    from hil.reports.html import plan_figure
    from hil.run.runner import run_plan

    figures: dict = {}
    with tempfile.TemporaryDirectory() as tmp:
        for png, (plan_file, title) in FIGURES.items():
            plan = load_plan(PLANS / plan_file)
            spec = next(s for s in plan.plots if s.title == title)
            result, signals = run_plan(plan, seed=0, reports=False)
            end_s = signals.end_s if len(signals) else result.sim_duration_s
            b64 = plan_figure(spec, signals, result.marks, end_s)
            a, b = _window(spec, result, signals)
            counts = result.counts()
            entry = {"plan": f"test_plans/{plan_file}", "profile": result.profile or "paper",
                     "plot": title, "outcome": result.outcome.value,
                     "checks_passed": f"{counts['PASS'] + counts['MARGINAL']}/"
                                      f"{sum(counts.values()) - counts.get('INFO', 0)}",
                     "window_s": [round(a, 4), round(b, 4)]}
            if png == "speed_step.png":
                entry["speed_ref_rpm_levels"] = _levels(signals["cmd.speed_ref_rpm"], a, b, "rpm")
                entry["step_at_s"] = round(result.marks["step"], 4)
                entry["plant_speed_rpm_final"] = round(
                    _mean(signals["plant.speed_rpm"], b - 0.05, b, "rpm"), 1)
            elif png == "flux_locus.png":
                entry["speed_ref_rpm_levels"] = _levels(signals["cmd.speed_ref_rpm"], a, b, "rpm")
                entry["plant_speed_rpm_mean"] = round(_mean(signals["plant.speed_rpm"], a, b, "rpm"), 1)
                psi = signals["plant.psi_alpha"].window(a, b).to_unit("Wb").values
                entry["psi_alpha_peak_wb"] = round(float(abs(psi).max()), 4)
            elif png == "ekf_speed.png":
                entry["speed_ref_rpm_levels"] = _levels(signals["cmd.speed_ref_rpm"], a, b, "rpm")
                err = (signals["ctrl.speed_ekf_rad_s"].window(a, b).to_unit("rpm").values
                       - signals["plant.speed_rpm"].window(a, b).to_unit("rpm")
                       .resampled(signals["ctrl.speed_ekf_rad_s"].window(a, b).t_s))
                entry["ekf_error_rpm_peak"] = round(float(abs(err).max()), 1)
            if b64 is None:
                entry["png"] = "not drawn: plan_figure had no data"
            elif chrome is None:
                entry["png"] = "not written: no Chromium"
            else:
                svg = Path(tmp) / png.replace(".png", ".svg")
                svg.write_bytes(base64.b64decode(b64))
                text = svg.read_text(encoding="utf-8")
                width = int(text.split('width="', 1)[1].split('"', 1)[0])
                height = int(text.split('height="', 1)[1].split('"', 1)[0])
                screenshot(chrome, svg.as_uri(), out_dir / png, width, height)
                entry["png"] = str(_shown(out_dir / png))
                entry["png_size_px"] = [width, height]
            figures[png] = entry
    return figures


def sweep_figure(out_dir: Path, chrome: str | None) -> dict:
    """Runs the tolerance sweep and screenshots its index.html into out_dir/sweep_summary.png;
    returns the figures of the page's caption."""
    from hil.sweep.format import load_sweep
    from hil.sweep.run import run_sweep

    sweep = load_sweep(SWEEP)
    with tempfile.TemporaryDirectory() as tmp:
        summary = run_sweep(sweep, Path(tmp) / "sweep", workers=SWEEP_WORKERS, progress=False)
        page = Path(tmp) / "sweep" / "index.html"
        entry: dict = {"sweep": str(SWEEP.relative_to(ROOT)), "workers": SWEEP_WORKERS,
                       "runs": summary["runs"], "ran": summary["ran"], "seed": sweep.seed,
                       "lost": summary["lost"],
                       "wall_s": round(summary["wall_s"], 1)}
        entry["plans"] = [{"plan": p["plan"], "runs": p["runs"], "judged": p["judged"],
                           "passed": p["passed"], "yield_pct": round(100 * p["yield"], 1),
                           "ci95_pct": [round(100 * p["ci_low"], 1), round(100 * p["ci_high"], 1)],
                           "outcomes": p["outcomes"]} for p in summary["plans"]]
        entry["failed_checks"] = [
            {"check": c["check"], "failed": c["failed"], "evaluated": c["evaluated"],
             "failed_runs": c["failed_runs"],
             "strongest_parameter": c["drivers"][0]["parameter"] if c["drivers"] else None,
             "rho_value": _r(c["drivers"][0]["rho_value"]) if c["drivers"] else None,
             "rho_fail": _r(c["drivers"][0]["rho_fail"]) if c["drivers"] else None}
            for c in summary["checks"] if c["failed"]]
        if chrome is None:
            entry["png"] = "not written: no Chromium; docs/img/sweep_summary.png is the old one"
        else:
            screenshot(chrome, page.as_uri(), out_dir / "sweep_summary.png", *SWEEP_WINDOW)
            entry["png"] = str(_shown(out_dir / "sweep_summary.png"))
            entry["png_size_px"] = list(SWEEP_WINDOW)
    return entry


def _r(x: float | None) -> float | None:
    return None if x is None else round(x, 4)


def _shown(path: Path) -> Path:
    try:
        return path.relative_to(ROOT)
    except ValueError:
        return path


def run(quick: bool = False) -> dict:
    chrome = browser()
    out: dict = {"browser": chrome or "none (chromium, chromium-browser, google-chrome, "
                                      "chromium-headless-shell not on PATH)"}
    if quick:
        with tempfile.TemporaryDirectory() as tmp:
            out["written_to"] = "a temporary directory (--quick leaves docs/img alone)"
            out["figures"] = plan_figures(Path(tmp), chrome)
        out["sweep_summary.png"] = "not made with --quick (no sweep)"
        return out
    IMG.mkdir(parents=True, exist_ok=True)
    out["written_to"] = str(IMG.relative_to(ROOT)) if chrome else "nothing (no Chromium)"
    out["figures"] = plan_figures(IMG, chrome)
    out["figures"]["sweep_summary.png"] = sweep_figure(IMG, chrome)
    return out
