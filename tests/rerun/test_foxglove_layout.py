"""docs/foxglove-layout.json plots what an eg2scope MCAP recording holds: every panel it places
is configured, every plotted path is a field of the ``/state/<bus>/<device>`` messages, and the
topics are the ones a recording of the sample CAN capture has."""

from __future__ import annotations

import json
import re
from typing import Any

import pytest
from mcap.reader import make_reader
from rerun_inputs import CAPTURES, ROOT

from analyzer.recording.recorder import McapRecorder
from analyzer.session.capture import CaptureOptions, run_capture

LAYOUT = ROOT / "docs" / "foxglove-layout.json"
PATH = re.compile(r"^(/state/[^.]+)\.(\w+)$")


def layout() -> dict[str, Any]:
    return json.loads(LAYOUT.read_text(encoding="utf-8"))


def placed(node: Any, config: dict[str, Any]) -> set[str]:
    """Panel ids in a layout tree, tabs included."""
    if isinstance(node, str):
        ids = {node}
        for tab in config.get(node, {}).get("tabs", []):
            ids |= placed(tab["layout"], config)
        return ids
    return placed(node["first"], config) | placed(node["second"], config)


@pytest.fixture(scope="module")
def recording(tmp_path_factory: pytest.TempPathFactory) -> tuple[set[str], set[str]]:
    """(topics, state message keys) of a recording of the sample CAN capture."""
    path = tmp_path_factory.mktemp("fox") / "can.mcap"
    run_capture(
        CaptureOptions(str(CAPTURES / "can_pick_place.log"), progress=False),
        [McapRecorder(path, metadata={})],
    )
    topics: set[str] = set()
    keys: set[str] = set()
    with path.open("rb") as f:
        for _, channel, message in make_reader(f).iter_messages():
            topics.add(channel.topic)
            if channel.topic.startswith("/state/"):
                keys |= set(json.loads(message.data))
    return topics, keys


def test_every_placed_panel_is_configured_and_every_configured_panel_placed() -> None:
    data = layout()
    assert placed(data["layout"], data["configById"]) == set(data["configById"])


def test_plots_read_fields_of_the_state_messages(recording: tuple[set[str], set[str]]) -> None:
    topics, keys = recording
    paths = [
        p["value"] for panel in layout()["configById"].values() for p in panel.get("paths", [])
    ]
    assert len(paths) > 20
    for path in paths:
        m = PATH.match(path)
        assert m, path
        assert m.group(2) in keys, path
    # the CAN bus of the sample capture: its two grippers are in the recording as plotted
    for device in (1, 2):
        assert f"/state/can0/{device}" in topics
        assert f"/state/can0/{device}.opening_mm" in paths
        assert f"/state/can0/{device}.force" in paths


def test_the_log_panels_read_the_event_topics(recording: tuple[set[str], set[str]]) -> None:
    topics, _ = recording
    logs = [
        c["topicToRender"] for k, c in layout()["configById"].items() if k.startswith("RosOut!")
    ]
    assert "/events/can0" in logs and "/events/can0" in topics
    assert all(t.startswith("/events/") for t in logs)
