# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""One definition of the events (firmware/protocol/schema.hpp, as tofmat._tofmat.protocol_schema()):
the Python client's streams and event types, docs/protocol.md and the daemon agree with it; the
`latest` poll serves a stream's last event."""

from __future__ import annotations

import dataclasses
import re
import time
from collections.abc import Callable
from typing import Any, get_args

import pytest
from conftest import REPO, Daemon

import tofmat
from tofmat import _tofmat
from tofmat.client import (
    STREAMS,
    DepthImage,
    DeviceEvent,
    Label,
    LabelMap,
    LineEvent,
    ResetEvent,
    SortDecision,
    Stream,
)

SCHEMA: list[dict[str, Any]] = _tofmat.protocol_schema()
BY_EVENT = {e["event"]: e for e in SCHEMA}

# Each event's Python type, and the fields it takes under another name or from the blob.
TYPES: dict[str, tuple[type, dict[str, str]]] = {
    "label": (Label, {}),
    "label_map": (LabelMap, {"width": "labels", "height": "labels"}),
    "depth": (DepthImage, {"width": "depth_mm", "height": "depth_mm", "dtype": "depth_mm"}),
    "device": (DeviceEvent, {}),
    "sort": (SortDecision, {}),
    "line": (LineEvent, {}),
    "reset": (ResetEvent, {}),
}


def test_the_clients_streams_are_the_schemas() -> None:
    from_schema = [s for e in SCHEMA for s in e["streams"]]
    assert set(STREAMS) == set(from_schema) == set(get_args(Stream))
    assert len(from_schema) == len(set(from_schema))  # a stream carries one kind of event


def test_every_event_has_a_python_type_holding_every_field() -> None:
    assert set(TYPES) == set(BY_EVENT)
    for event, (cls, renamed) in TYPES.items():
        names = {f.name for f in dataclasses.fields(cls)}
        for field in BY_EVENT[event]["fields"]:
            assert renamed.get(field["name"], field["name"]) in names, f"{event}.{field['name']} not in {cls.__name__}"


def _section(doc: str, event: str) -> str:
    m = re.search(rf"^### `{event}`.*?(?=^### |^## )", doc, re.M | re.S)
    assert m, f"docs/protocol.md has no section for the {event} event"
    return m.group(0)


def test_the_protocol_document_names_every_field_of_every_event() -> None:
    doc = (REPO / "docs" / "protocol.md").read_text()
    for e in SCHEMA:
        text = _section(doc, e["event"])
        for s in e["streams"]:
            assert f"`{s}`" in text, f"{e['event']}: stream {s} not named in its section"
        for f in e["fields"]:
            assert f"`{f['name']}`" in text, f"docs/protocol.md, {e['event']}: field {f['name']} not described"


def test_the_hello_offers_the_poll(start: Callable[..., Daemon]) -> None:
    d = start("sim:static,material=cork,depth=850,realtime=0")
    with d.client() as c:
        assert c.hello["minor"] == _tofmat.PROTOCOL_MINOR >= 5
        assert "latest" in c.hello["capabilities"]


def test_latest_serves_the_last_label_to_a_client_that_never_subscribed(start: Callable[..., Daemon]) -> None:
    d = start("sim:static,material=cork,depth=850,realtime=0")
    with d.client() as watcher:
        first = next(iter(watcher.labels(timeout=30)))  # the daemon has labelled a frame
    with d.client() as poller:  # a fresh client: no subscription
        label = poller.latest_label()
        assert isinstance(label, Label) and label.frame >= first.frame
        assert label.truth is not None and label.truth.material == "cork" and label.simulated
        device = poller.latest("device")
        assert isinstance(device, DeviceEvent) and device.state == "streaming"
        assert poller.latest("reset") is None  # nothing was reset: no event, not an empty one
        time.sleep(0.3)
        later = poller.latest_label()
        assert later is not None and later.frame >= label.frame
        for stream, says in (("label_map", "carries images"), ("depth:combined", "carries images"),
                             ("sparkles", "unknown stream")):  # fmt: skip
            with pytest.raises(tofmat.CommandError, match=says):
                poller.latest(stream)


def test_a_reset_is_the_latest_reset_event(start: Callable[..., Daemon]) -> None:
    d = start("sim:static,material=cork,depth=850,realtime=0")
    with d.client() as c:
        c.reset()
        deadline = time.monotonic() + 10
        event = c.latest("reset")
        while event is None and time.monotonic() < deadline:
            time.sleep(0.05)
            event = c.latest("reset")
        assert isinstance(event, ResetEvent) and event.by == "command"
