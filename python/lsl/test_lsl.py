"""`thermode serve --lsl` judged by a pylsl inlet: the telemetry stream's description, its samples at the loop rate
(at least 99.9 % received), marker timestamps against the telemetry samples (within one loop period), and a
program's segment starts and responses as markers on the ticks the daemon's replies name.

liblsl is kept on this machine: `LSLAPICFG` points both the daemon and this inlet at a configuration with the
machine resolve scope, IPv6 off, loopback as the only known peer and a session id of its own, so nothing leaves the
machine and no other LSL stream on it is seen.

Needs `pylsl` (which ships liblsl); skipped without it unless `THERMODE_REQUIRE_PYTHON_TESTS=1` (CI), where a missing
module is a failure. `THERMODE_LSL_SECONDS` sets the length of the sample count (default 10 s; the 60 s judgement is
`THERMODE_LSL_SECONDS=60`).
"""

from __future__ import annotations

import json
import os
import tempfile
import time
import uuid
from pathlib import Path
from typing import Iterator, List, Tuple

import pytest

SESSION = f"thermode-test-{uuid.uuid4().hex[:12]}"
_CONFIG = Path(tempfile.mkdtemp(prefix="thermode-lsl-")) / "lsl_api.cfg"
_CONFIG.write_text(
    "[ports]\nIPv6 = disable\n[multicast]\nResolveScope = machine\n"
    f"[lab]\nKnownPeers = {{127.0.0.1}}\nSessionID = {SESSION}\n"
)
os.environ["LSLAPICFG"] = str(_CONFIG)

if os.environ.get("THERMODE_REQUIRE_PYTHON_TESTS") == "1":
    import pylsl  # noqa: E402  (a missing module fails the run in CI)
else:
    pylsl = pytest.importorskip("pylsl", reason="`python3 -m pip install pylsl` to run the LSL tests")

from conftest import Daemon  # noqa: E402
from thermode_client import Client  # noqa: E402

RATE_HZ = 100.0
PERIOD_S = 1.0 / RATE_HZ
CHANNELS = 5
FIELDS = ["target_c", "skin_c", "sensor_c", "setpoint_c", "current_a"]
NAME = f"thermode-{uuid.uuid4().hex[:8]}"


@pytest.fixture(scope="module")
def lsl_daemon() -> Iterator[Daemon]:
    running = Daemon("--lsl", "--lsl-name", NAME, "--channels", str(CHANNELS))
    yield running
    running.stop()


def inlet(stream: str) -> "pylsl.StreamInlet":
    found = pylsl.resolve_byprop("name", stream, minimum=1, timeout=15.0)
    assert found, f"no LSL stream named {stream!r} within 15 s"
    opened = pylsl.StreamInlet(found[0], max_buflen=360)
    opened.open_stream(timeout=10.0)
    return opened


def pull(opened: "pylsl.StreamInlet", seconds: float) -> Tuple[List[List[float]], List[float]]:
    samples: List[List[float]] = []
    stamps: List[float] = []
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        chunk, times = opened.pull_chunk(timeout=0.2, max_samples=4096)
        samples.extend(chunk)
        stamps.extend(times)
    return samples, stamps


def test_the_telemetry_stream_describes_every_channel_with_its_unit(lsl_daemon) -> None:
    info = inlet(f"{NAME} telemetry").info(timeout=10.0)
    assert info.channel_count() == CHANNELS * len(FIELDS), info.channel_count()
    assert info.nominal_srate() == RATE_HZ, info.nominal_srate()
    assert info.channel_format() == pylsl.cf_double64
    channel = info.desc().child("channels").child("channel")
    labels, units = [], []
    while not channel.empty():
        labels.append(channel.child_value("label"))
        units.append(channel.child_value("unit"))
        channel = channel.next_sibling()
    expected = [f"ch{c}_{f}" for c in range(CHANNELS) for f in FIELDS]
    assert labels == expected, labels
    assert units == ["A" if f == "current_a" else "degC" for _ in range(CHANNELS) for f in FIELDS], units


def test_at_least_999_per_mille_of_the_samples_arrive_at_the_loop_rate(lsl_daemon) -> None:
    seconds = float(os.environ.get("THERMODE_LSL_SECONDS", "10"))
    telemetry = inlet(f"{NAME} telemetry")
    with Client(lsl_daemon.url) as display:
        missed_before = display.status()["loop"]["missed_deadlines"]
        samples, stamps = pull(telemetry, seconds)
        missed_after = display.status()["loop"]["missed_deadlines"]
    assert len(samples) > 0.5 * seconds * RATE_HZ, f"{len(samples)} samples in {seconds} s"
    assert all(len(s) == CHANNELS * len(FIELDS) for s in samples)
    span_s = stamps[-1] - stamps[0]
    nominal = round(span_s / PERIOD_S) + 1
    # Deadlines the loop itself missed (a loaded machine) have no tick and so no sample: not an LSL loss.
    expected = nominal - (missed_after - missed_before)
    received = len(set(round(t / PERIOD_S) for t in stamps))
    ratio = received / expected
    print(
        f"LSL telemetry: {received} of {expected} samples ({100 * ratio:.3f} %) over {span_s:.2f} s at {RATE_HZ} Hz x "
        f"{CHANNELS} channels; {missed_after - missed_before} deadlines missed by the loop; nominal {nominal}"
    )
    assert ratio >= 0.999, f"received {received}, expected {expected} (ratio {ratio:.5f} < 0.999)"
    steps = [b - a for a, b in zip(stamps, stamps[1:])]
    assert min(steps) > 0.5 * PERIOD_S, f"timestamps not increasing by a period: smallest step {min(steps)}"


def pull_with_events(
    telemetry: "pylsl.StreamInlet", markers: "pylsl.StreamInlet"
) -> Tuple[List[List[float]], List[float], List[Tuple[dict, float]]]:
    """A second of telemetry (samples, stamps), then a second of markers, each parsed with its stamp."""
    samples, stamps = pull(telemetry, 1.0)
    texts, times = pull(markers, 1.0)
    return samples, stamps, [(json.loads(t[0]), s) for t, s in zip(texts, times)]


def nearest(stamps: List[float], t: float) -> float:
    return min(stamps, key=lambda s: abs(s - t))


def test_markers_carry_the_timestamp_of_their_telemetry_sample(lsl_daemon) -> None:
    telemetry = inlet(f"{NAME} telemetry")
    markers = inlet(f"{NAME} markers")
    time.sleep(0.3)
    with Client(lsl_daemon.url) as display:
        offset_s = display.status()["lsl"]["lsl_offset_s"]
        touched = display.touch(1, "aluminium")
        time.sleep(1.0)
        noted = display.marker("trial 1 start", channel=1)
        time.sleep(0.2)
        display.stop_all()
        time.sleep(0.5)
    samples, stamps, events = pull_with_events(telemetry, markers)
    kinds = [e["event"] for e, _ in events]
    assert ["touch", "marker", "stop"] == [k for k in kinds if k in ("touch", "marker", "stop")], kinds

    touch, touch_s = next((e, s) for e, s in events if e["event"] == "touch")
    assert touch["channel"] == 1 and touch["material"] == "aluminium", touch
    # The touch marker is stamped with the tick that applied it, which the daemon's reply names.
    assert abs(touch_s - (touched.time_s + offset_s)) < 1e-6, (touch_s, touched.time_s + offset_s)
    assert abs(nearest(stamps, touch_s) - touch_s) < 1e-6, "no telemetry sample at the touch marker's tick"
    # The channel's target falls once aluminium is touched (heat flows into the cold metal): the samples after the
    # marker show it, the one before does not yet.
    target = FIELDS.index("target_c") + len(FIELDS) * 1
    before = [s[target] for s, t in zip(samples, stamps) if t < touch_s]
    after = [s[target] for s, t in zip(samples, stamps) if touch_s + 0.5 <= t <= touch_s + 1.0]
    assert before and after and max(after) < before[-1] - 1.0, (before[-1:], after[:3])

    marker, marker_s = next((e, s) for e, s in events if e["event"] == "marker")
    assert marker["text"] == "trial 1 start" and marker["channel"] == 1, marker
    assert abs(marker_s - noted.fields["lsl_time_s"]) < 1e-6, (marker_s, noted.fields)
    gap_s = abs(nearest(stamps, marker_s) - marker_s)
    assert gap_s <= PERIOD_S, f"client marker {gap_s:.4f} s from the nearest telemetry sample (> {PERIOD_S} s)"

    stop_s = next(s for e, s in events if e["event"] == "stop")
    assert abs(nearest(stamps, stop_s) - stop_s) < 1e-6, "no telemetry sample at the stop marker's tick"
    current = FIELDS.index("current_a") + len(FIELDS) * 1
    after_stop = [s[current] for s, t in zip(samples, stamps) if t >= stop_s]
    assert after_stop and all(a == 0.0 for a in after_stop), after_stop[:5]


def test_program_events_are_markers_on_the_tick_that_applied_them(lsl_daemon) -> None:
    """A program's segment starts and a response join the marker stream, stamped with the tick the daemon's replies
    name (the program's `start_time_s`, the response's `time_s`), each on a telemetry sample."""
    telemetry = inlet(f"{NAME} telemetry")
    markers = inlet(f"{NAME} markers")
    time.sleep(0.3)
    with Client(lsl_daemon.url) as display:
        offset_s = display.status()["lsl"]["lsl_offset_s"]
        started = display.program({2: [{"to_c": 25.0, "rate_c_s": 1.0, "until": "response"}, {"to_c": 32.0, "rate_c_s": 5.0}]})
        time.sleep(0.8)
        answered = display.response(2)
        time.sleep(0.3)
        display.stop_all()
        time.sleep(0.3)
    _, stamps, events = pull_with_events(telemetry, markers)
    program = [(e, s) for e, s in events if e["event"] in ("segment_start", "response") and e.get("channel") == 2]
    kinds = [(e["event"], e.get("segment")) for e, _ in program]
    assert kinds == [("segment_start", 0), ("response", 0), ("segment_start", 1)], kinds
    start_s = started.fields["start_time_s"] + offset_s
    (first, first_s), (response, response_s), (second, second_s) = program
    assert first["tick"] == started.fields["start_tick"], (first, started.fields)
    assert abs(first_s - start_s) < 1e-6, (first_s, start_s)
    assert response["tick"] == answered.tick and second["tick"] == answered.tick, (response, second, answered)
    assert abs(response_s - (answered.time_s + offset_s)) < 1e-6, (response_s, answered.time_s + offset_s)
    assert abs(second_s - response_s) < 1e-9, (second_s, response_s)
    for stamp in (first_s, response_s):
        assert abs(nearest(stamps, stamp) - stamp) < 1e-6, "no telemetry sample at a program marker's tick"
