"""`ThermodeDevice` against a real `thermode serve`, and the PsychoPy entry point it declares."""

from __future__ import annotations

import tomllib
from pathlib import Path

from psychopy_thermode import ThermodeDevice


def test_the_device_touches_sets_and_stops_its_channel(daemon) -> None:
    device = ThermodeDevice(url=daemon.url, channel=2)
    assert 20.0 < device.finger_temperature_c() < 40.0
    device.touch("wood")
    assert device.temperatures()["mode"] == "touch"
    device.setpoint(34.0, rate_c_s=2.0)
    assert device.temperatures()["mode"] == "direct"
    device.stop()
    assert device.temperatures()["held_off"] is True
    assert device.isSameDevice({"url": daemon.url, "channel": 2})
    device.close()


def test_the_plugin_declares_psychopys_hardware_entry_point() -> None:
    project = tomllib.loads((Path(__file__).resolve().parents[1] / "pyproject.toml").read_text())
    hardware = project["project"]["entry-points"]["psychopy.hardware"]
    module, _, name = hardware["ThermodeDevice"].partition(":")
    assert (module, name) == ("psychopy_thermode.device", "ThermodeDevice")
    assert getattr(__import__(module, fromlist=[name]), name) is ThermodeDevice
