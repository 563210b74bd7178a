"""`ThermodeDevice`: one channel (finger) of a thermode display as a PsychoPy hardware device.

It subclasses PsychoPy's `psychopy.hardware.base.BaseDevice` when PsychoPy is installed (so PsychoPy's device
manager can hold it) and a plain object otherwise; everything it does goes through `thermode_client.Client` to a
running `thermode serve`, whose safety envelope bounds every stimulus.
"""

from __future__ import annotations

from typing import Any, Dict, List, Optional, Sequence, Union

from thermode_client import Client, Reply, ThermodeError

try:  # PsychoPy is optional: the plugin works (and is tested) without it.
    from psychopy.hardware.base import BaseDevice as _Base
except ImportError:  # pragma: no cover - depends on the environment
    _Base = object


class ThermodeDevice(_Base):  # type: ignore[misc, valid-type]
    """One channel of a thermode display.

    `url`: the daemon's WebSocket address (`thermode serve` prints it). `channel`: the finger, from 0. `token`: the
    daemon's `--token`, if any. `timeout_s`: how long a request waits for its reply [s].
    """

    def __init__(self, url: str = "ws://127.0.0.1:8765/api/ws", channel: int = 1, token: Optional[str] = None,
                 timeout_s: float = 5.0) -> None:
        if _Base is not object:
            super().__init__()
        self.channel = channel
        self.client = Client(url, token=token, timeout_s=timeout_s)

    def touch(self, material: Union[str, Dict[str, Any]], object_temp_c: Optional[float] = None) -> Reply:
        """Show `material` (a library name or a dict of properties) at `object_temp_c` [°C] on this channel."""
        return self.client.touch(self.channel, material, object_temp_c)

    def release(self) -> Reply:
        """End the stimulus: the channel renders air."""
        return self.client.release(self.channel)

    def setpoint(self, temp_c: float, rate_c_s: float = 2.0) -> Reply:
        """Ramp the display to `temp_c` [°C] at `rate_c_s` [°C/s] (the paper's display rate is 2 °C/s)."""
        return self.client.setpoint(self.channel, temp_c, rate_c_s)

    def program(self, segments: Sequence[Dict[str, Any]]) -> Reply:
        """Run a stimulus program on this channel: segments `{"to_c": T, "rate_c_s": R}` (a ramp), `{"to_c": T}` (a
        step) or `{"hold_s": D}` (a hold), a ramp or hold optionally with `"until": "response"` (at most 999). A
        method-of-limits run from 32 °C: `[{"to_c": 0, "rate_c_s": 1, "until": "response"}, {"to_c": 32,
        "rate_c_s": 1}]` (0 °C is clipped to the display's range; the reply's `fields["cutoff_c"]` says where)."""
        return self.client.program({self.channel: segments})

    def program_stop(self) -> Reply:
        """End this channel's program; its set-point holds where the program left it."""
        return self.client.program_stop(self.channel)

    def respond(self, kind: str = "button", value: Optional[float] = None) -> Reply:
        """The participant responded (e.g. a key press in a PsychoPy routine): a "button", or a "rating" with
        `value` 0–100. The reply's `fields` hold the plate's `sensor_c` and `setpoint_c` at the response's tick."""
        return self.client.response(self.channel, kind, value)

    def wait_for_response(self, timeout_s: Optional[float] = None) -> Dict[str, Any]:
        """Wait for a response on this channel from any client (a button box, the dashboard, `respond`): the
        `response` event with its `tick`, `time_s`, `sensor_c` and `setpoint_c`."""
        return self.client.wait_for_response(self.channel, timeout_s=timeout_s)

    def wait_for_program_end(self, timeout_s: Optional[float] = None) -> Dict[str, Any]:
        """Wait until this channel's program has run its last segment."""
        return self.client.wait_for_program_end(self.channel, timeout_s=timeout_s)

    def temperatures(self) -> Dict[str, Any]:
        """This channel's entry of the daemon's status: `sensor_c`, `plate_estimate_c`, `target_skin_c`, `fault`…"""
        return self.client.status()["channels"][self.channel]

    def finger_temperature_c(self) -> float:
        """The display's sensor now [°C]: with the finger resting on a display that renders air, its skin."""
        return float(self.temperatures()["sensor_c"])

    def stop(self) -> Reply:
        """Stop all channels: released, drives held at 0 A until their next command."""
        return self.client.stop_all()

    def close(self) -> None:
        """Release this channel (if the connection still stands) and close the connection."""
        try:
            self.release()
        except ThermodeError:
            pass
        self.client.close()

    # PsychoPy's device manager asks devices to describe and check themselves.
    def isSameDevice(self, other: Any) -> bool:  # noqa: N802 (PsychoPy's name)
        """Whether `other` is the same channel of the same daemon."""
        if isinstance(other, ThermodeDevice):
            return (other.client.url, other.channel) == (self.client.url, self.channel)
        if isinstance(other, dict):
            return (other.get("url"), other.get("channel")) == (self.client.url, self.channel)
        return False

    @staticmethod
    def getAvailableDevices() -> List[Dict[str, Any]]:  # noqa: N802 (PsychoPy's name)
        """The default local daemon's five fingers (a running daemon's status lists its own channels)."""
        return [{"deviceName": f"thermode channel {k}", "url": "ws://127.0.0.1:8765/api/ws", "channel": k}
                for k in range(5)]
