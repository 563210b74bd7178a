"""The client against a real `thermode serve` on the simulated display: every request, telemetry beside requests,
refusals as `ThermodeError` with the daemon's code, the token, and a closed daemon."""

from __future__ import annotations

import threading

import pytest

from thermode_client import Client, ThermodeError


def test_touch_cools_the_finger_and_release_returns_to_air(daemon) -> None:
    with Client(daemon.url) as display:
        reply = display.touch(1, "aluminium")
        assert reply.request == "touch" and reply.tick is not None and reply.time_s is not None
        status = display.status()["channels"][1]
        assert status["mode"] == "touch" and status["material"] == "aluminium"
        frames = list(display.subscribe(rate_hz=20, count=20))
        assert len(frames) == 20
        ticks = [frame.tick for frame in frames]
        assert ticks == sorted(ticks) and len(set(ticks)) == 20, ticks
        # Aluminium at 23 °C draws heat: the target falls below the resting skin within a second.
        first, last = frames[0].channels[1], frames[-1].channels[1]
        assert last["target_skin_c"] < first["target_skin_c"] - 1.0, (first, last)
        assert "plate_estimate_c" in last and "cem43_min" in last
        display.release(1)
        assert display.status()["channels"][1]["mode"] == "air"


def test_a_custom_material_and_a_direct_setpoint(daemon) -> None:
    with Client(daemon.url) as display:
        glass = {"name": "cold-glass", "conductivity_w_mk": 1.0, "density_kg_m3": 2500, "specific_heat_j_kgk": 840}
        assert display.touch(0, glass, object_temp_c=10.0).fields["material"] == "cold-glass"
        reply = display.setpoint(2, temp_c=36.0, rate_c_s=2.0)
        assert reply.request == "setpoint"
        channel = display.status()["channels"][2]
        assert channel["mode"] == "direct" and channel["direct_temp_c"] == 36.0
        display.stop_all()
        assert all(c["held_off"] for c in display.status()["channels"])


def test_refusals_raise_with_the_daemons_code_and_change_nothing(daemon) -> None:
    with Client(daemon.url) as display:
        display.release(3)
        with pytest.raises(ThermodeError) as refused:
            display.touch(3, "kryptonite")
        assert refused.value.code == "unknown_material", refused.value
        with pytest.raises(ThermodeError) as refused:
            display.setpoint(3, temp_c=80.0, rate_c_s=2.0)
        assert refused.value.code == "bad_value", refused.value
        with pytest.raises(ThermodeError) as refused:
            display.touch(99, "wood")
        assert refused.value.code == "unknown_channel", refused.value
        assert display.status()["channels"][3]["mode"] == "air"


def test_requests_from_another_thread_while_telemetry_streams(daemon) -> None:
    with Client(daemon.url) as display:
        replies = []

        def toucher() -> None:
            for material in ["wood", "steel", "rubber"]:
                replies.append(display.touch(4, material).fields["material"])

        frames = []
        thread = threading.Thread(target=toucher)
        for frame in display.subscribe(rate_hz=50, count=30):
            if not thread.is_alive() and not replies:
                thread.start()
            frames.append(frame)
        thread.join(timeout=10)
        assert replies == ["wood", "steel", "rubber"]
        assert len(frames) == 30
        display.release(4)


def test_the_token_is_required_and_accepted(token_daemon) -> None:
    with pytest.raises(Exception):
        Client(token_daemon.url, timeout_s=2.0)
    with Client(token_daemon.url, token="s3cret-token") as display:
        assert display.status()["auth"]["token_required"] is True
        display.release(0)


def test_a_closed_connection_is_an_error_not_a_hang(daemon) -> None:
    display = Client(daemon.url, timeout_s=2.0)
    display.close()
    with pytest.raises(ThermodeError) as closed:
        display.release(0)
    assert closed.value.code == "connection_closed"
