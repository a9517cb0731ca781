"""The Foxglove layouts in docs/foxglove/ (issue 17) load as JSON and name only topics and
fields the bench publishes (the MCAP log's channels; the live stream carries the full-rate
ones under the same names and schemas)."""
from __future__ import annotations

import json
from pathlib import Path

import pytest

from plant_rt import TRUTH_FIELDS

from hil.logs.recorder import COMMAND_FIELDS, SENSOR_FIELDS, TELEMETRY_FIELDS

LAYOUTS = sorted((Path(__file__).resolve().parents[1] / "docs" / "foxglove").glob("*.json"))
FIELDS = {
    "/plant/truth": set(TRUTH_FIELDS),
    "/plant/sensors": {"period", *SENSOR_FIELDS},
    "/ctrl/telemetry": {"period", *TELEMETRY_FIELDS},
    "/cmd": {"period", *COMMAND_FIELDS},
}


def message_paths(layout: dict) -> list[str]:
    out = []
    for config in layout["configById"].values():
        out += [p["value"] for p in config.get("paths", [])]
        if "xAxisPath" in config:
            out.append(config["xAxisPath"]["value"])
    return out


def unknown_paths(layout: dict) -> list[str]:
    bad = []
    for path in message_paths(layout):
        topic, _, field = path.rpartition(".")
        if field not in FIELDS.get(topic, ()):
            bad.append(path)
    return bad


def test_there_is_a_layout_per_figure_group():
    assert {p.stem for p in LAYOUTS} >= {"speed_step", "flux_locus", "estimates_vs_truth",
                                         "rotor_position", "currents"}


@pytest.mark.parametrize("path", LAYOUTS, ids=[p.stem for p in LAYOUTS])
def test_layout_names_only_published_topics_and_fields(path):
    layout = json.loads(path.read_text())
    assert message_paths(layout)
    assert unknown_paths(layout) == []


def test_a_misspelt_field_is_caught():
    layout = {"configById": {"Plot!x": {"paths": [{"value": "/plant/truth.speed_rmp"}]}}}
    assert unknown_paths(layout) == ["/plant/truth.speed_rmp"]
