"""Every message of a real session, both ways, and the HTTP bodies are instances of the published JSON Schema of the
protocol (`docs/protocol.schema.json`, generated from the daemon's serde types): the client and the daemon speak
the same vocabulary."""

from __future__ import annotations

import json
import os
import urllib.request
from pathlib import Path

import pytest

from thermode_client import Client, ThermodeError

try:
    import jsonschema
except ImportError:
    if os.environ.get("THERMODE_REQUIRE_PYTHON_TESTS"):
        raise
    pytest.skip("the schema checks need the `jsonschema` module (pip install jsonschema)", allow_module_level=True)

SCHEMA = json.loads((Path(__file__).resolve().parents[3] / "docs" / "protocol.schema.json").read_text())


def validator(definition: str):
    """A validator of one of the schema's `$defs`."""
    schema = {"$schema": SCHEMA["$schema"], "$defs": SCHEMA["$defs"], "$ref": f"#/$defs/{definition}"}
    return jsonschema.Draft202012Validator(schema)


def assert_valid(definition: str, message) -> None:
    errors = sorted(validator(definition).iter_errors(message), key=lambda e: list(e.path))
    assert not errors, f"{definition}: {json.dumps(message)[:400]} -> {[e.message for e in errors[:3]]}"


def recorded(client: Client):
    """Wraps the client's socket so that every text sent and received is kept."""
    sent, received = [], []
    ws = client._ws
    send, recv = ws.send, ws.recv

    def recording_send(text, *args, **kwargs):
        sent.append(json.loads(text))
        return send(text, *args, **kwargs)

    def recording_recv(*args, **kwargs):
        text = recv(*args, **kwargs)
        received.append(json.loads(text))
        return text

    ws.send, ws.recv = recording_send, recording_recv
    return sent, received


def http_json(daemon, path: str):
    url = daemon.url.replace("ws://", "http://").replace("/api/ws", path)
    with urllib.request.urlopen(url, timeout=5) as response:
        return json.loads(response.read().decode("utf-8"))


def test_a_session_both_ways_is_valid_against_the_published_schema(daemon) -> None:
    with Client(daemon.url) as client:
        sent, received = recorded(client)
        client.touch(1, "aluminium", object_temp_c=20.0)
        client.touch(2, {"conductivity_w_mk": 0.2, "density_kg_m3": 1200, "specific_heat_j_kgk": 1500, "name": "pla"})
        list(client.subscribe(50, count=3))
        client.setpoint(3, 30.0, 2.0)
        client.marker("trial 1", channel=1)
        client.request({"type": "status"})
        with pytest.raises(ThermodeError):
            client.touch(9, "wood")
        with pytest.raises(ThermodeError):
            client.request({"type": "touch", "channel": 0, "material": "wood", "colour": "red"})
        client.clear_fault(0)
        client.release(1)
        client.stop_all()
    kinds = {message["type"] for message in received}
    assert {"ok", "error", "status", "telemetry"} <= kinds, kinds
    for message in sent:
        if message.get("colour") is None:
            assert_valid("ClientMessage", message)
    with pytest.raises(AssertionError):
        assert_valid("ClientMessage", {"type": "touch", "id": 1, "channel": 0, "material": "wood", "colour": "red"})
    for message in received:
        assert_valid("Response", message)
    assert_valid("Status", http_json(daemon, "/api/status"))
    assert_valid("MaterialList", http_json(daemon, "/api/materials"))
    assert_valid("History", http_json(daemon, "/api/history"))
