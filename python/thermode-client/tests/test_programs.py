"""Programs and responses through the client against a real `thermode serve` on the simulated display: a method-of-
limits run stopped by a response (the reply carries the plate at the response's tick, the events follow), the
cut-off of a target beyond the display's range, the segment limit, and the PsychoPy plugin's helpers."""

from __future__ import annotations

import pytest

from psychopy_thermode import ThermodeDevice
from thermode_client import MAX_SEGMENTS, Client, ThermodeError


def test_a_response_ends_a_limits_ramp_and_the_events_follow(daemon) -> None:
    with Client(daemon.url) as display:
        display.release(0)
        reply = display.program({0: [{"to_c": 0, "rate_c_s": 1, "until": "response"}, {"to_c": 32, "rate_c_s": 5}]})
        start_tick = reply.fields["start_tick"]
        assert reply.request == "program" and reply.fields["channels"] == [0]
        limits = display.status()["limits"]
        assert reply.fields["cutoff_c"] == limits["display_min_c"], reply.fields
        assert reply.fields["cutoffs"][0]["requested_c"] == 0.0
        first = display.wait_for_event("segment_start", channel=0, after_tick=start_tick)
        assert (first["tick"], first["segment"]) == (start_tick, 0), first
        assert first["cutoff_c"] == limits["display_min_c"], first
        answered = display.response(0)
        assert answered.request == "response" and answered.fields["ended_segment"] == 0, answered.fields
        assert answered.tick is not None and answered.tick > start_tick
        assert answered.fields["sensor_c"] is not None and answered.fields["setpoint_c"] is not None
        assert answered.fields["setpoint_c"] < 32.0, answered.fields
        event = display.wait_for_response(channel=0)
        assert event["tick"] == answered.tick and event["kind"] == "button", event
        back = display.wait_for_event("segment_start", channel=0, after_tick=answered.tick)
        assert (back["tick"], back["segment"]) == (answered.tick, 1), back
        end = display.wait_for_program_end(channel=0, timeout_s=10)
        assert end["tick"] > answered.tick and abs(end["setpoint_c"] - 32.0) < 1e-6, end


def test_a_rating_a_stop_and_the_segment_limit(daemon) -> None:
    with Client(daemon.url) as display:
        display.program({3: [{"hold_s": 30, "until": "response"}, {"hold_s": 30}]})
        rating = display.response(3, "rating", 62.5)
        assert rating.fields["value"] == 62.5 and rating.fields["ended_segment"] == 0, rating.fields
        assert display.program_stop(3).request == "program_stop"
        assert display.status()["channels"][3]["program_segment"] is None
        hold = {"hold_s": 0.01}
        assert display.program({3: [hold] * MAX_SEGMENTS}).request == "program"
        with pytest.raises(ThermodeError) as refused:
            display.program({3: [hold] * (MAX_SEGMENTS + 1)})
        assert refused.value.code == "bad_value" and "999" in refused.value.message, refused.value
        with pytest.raises(ThermodeError) as refused:
            display.response(3, "rating", 140)
        assert refused.value.code == "bad_value", refused.value
        display.release(3)


def test_the_psychopy_device_runs_a_program_and_waits_for_its_end(daemon) -> None:
    device = ThermodeDevice(url=daemon.url, channel=4)
    reply = device.program([{"to_c": 33, "rate_c_s": 4, "until": "response"}, {"hold_s": 0.2}])
    assert reply.fields["cutoff_c"] is None
    device.respond()
    device.wait_for_response(timeout_s=5)
    end = device.wait_for_program_end(timeout_s=5)
    assert end["channel"] == 4
    device.close()
