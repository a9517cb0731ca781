"""`hil` imports hil.cli.main with the cyclic GC on (main() turns it off before the command's
imports, see hil.cli.main.main), so the module itself imports next to nothing: json and
hil.links.registry (configfile, yaml, protocol, ctypes) come with the functions that use them.
Those paths still find them: the link choices in --help, `hil log info --json`."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

from hil.cli.main import main as hil_main
from hil.links.registry import LINK_CHOICES

ROOT = Path(__file__).resolve().parents[1]

PLAN = """name: two-periods
steps:
  - run: {duration_s: 100.0e-6}
  - check: {name: ran, kind: final_value, signal: plant.speed_rpm, limits: {low: -1, high: 1, unit: rpm}}
"""


def test_importing_the_command_imports_neither_the_registry_nor_json():
    code = ("import sys\nfrom hil.cli import main\n"
            "print(sorted(m for m in ('hil.links.registry', 'json', 'yaml', 'protocol') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, check=True)
    assert out.stdout.strip() == "[]"


def test_run_and_serve_help_name_the_link_choices(capsys):
    for command in ("run", "serve"):
        try:
            hil_main([command, "--help"])
        except SystemExit as exc:
            assert exc.code == 0
        text = " ".join(capsys.readouterr().out.split())
        assert ", ".join(LINK_CHOICES) in text.replace("- ", "-")


def test_log_info_json_of_a_run(tmp_path, capsys):
    plan = tmp_path / "plan.yaml"
    plan.write_text(PLAN)
    assert hil_main(["run", str(plan), "--out", str(tmp_path / "out"), "--no-progress"]) == 0
    capsys.readouterr()
    log = tmp_path / "out" / "two-periods" / "log.mcap"
    assert hil_main(["log", "info", str(log), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["channels"]
