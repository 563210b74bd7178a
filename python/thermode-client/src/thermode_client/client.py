"""The blocking client of the thermode contact API (`docs/api.md`): one WebSocket connection to `thermode serve`.

A reader thread takes every message off the connection: replies go to the request that waits for them (matched by
`id`), telemetry frames to a queue that `subscribe` reads, program events (a segment's start, a response, a
program's end) to a queue that `wait_for_event`, `wait_for_response` and `wait_for_program_end` read. So requests
may be made while another thread iterates over telemetry, and none loses another's messages.
"""

from __future__ import annotations

import contextlib
import itertools
import json
import queue
import threading
import urllib.parse
import urllib.request
from dataclasses import dataclass, field
import time
from typing import Any, Dict, Iterator, List, Mapping, Optional, Sequence, Union

from websockets.exceptions import ConnectionClosed
from websockets.sync.client import ClientConnection, connect

#: Seconds a request waits for its reply before `ThermodeError("timeout")`. Default 5 (the daemon answers within a
#: loop tick or its 1 s reply timeout).
DEFAULT_TIMEOUT_S = 5.0

#: Telemetry frames kept for `subscribe` before the oldest are dropped. Default 10 000 (100 s at 100 Hz).
TELEMETRY_QUEUE_LEN = 10_000

#: Program events kept for the `wait_for_*` helpers before the oldest are dropped. Default 10 000.
EVENT_QUEUE_LEN = 10_000

#: Most segments of one channel's program (the daemon refuses more, naming the limit).
MAX_SEGMENTS = 999

Json = Dict[str, Any]


class ThermodeError(Exception):
    """The daemon refused a request (nothing changed), or the connection failed.

    `code` is the daemon's error code (`docs/api.md`), or `timeout` / `connection_closed` for the client's own
    failures; `message` its explanation.
    """

    def __init__(self, code: str, message: str) -> None:
        super().__init__(f"{code}: {message}")
        self.code = code
        self.message = message


@dataclass(frozen=True)
class Reply:
    """A successful reply: the request's name, and for changes of a channel the loop `tick` and `time_s` [s] of the
    first drive command that carries it. `fields` holds the whole reply."""

    request: str
    tick: Optional[int]
    time_s: Optional[float]
    fields: Json = field(repr=False)


@dataclass(frozen=True)
class Telemetry:
    """One telemetry frame: loop `time_s` [s], `tick`, and one dict per channel with the `render` CSV's names
    (`target_skin_c`, `skin_c`, `display_setpoint_c`, `sensor_c`, `plate_estimate_c`, `current_a`, `fault`, …)."""

    time_s: float
    tick: int
    channels: List[Json]


class Client:
    """A connection to `thermode serve`. Use it as a context manager, or call `close()`.

    `url`: the WebSocket address, e.g. `ws://127.0.0.1:8765/api/ws`. `token`: the daemon's `--token`, if any.
    `timeout_s`: how long a request waits for its reply [s].
    """

    def __init__(self, url: str, token: Optional[str] = None, timeout_s: float = DEFAULT_TIMEOUT_S) -> None:
        self.url = url
        self.token = token
        self.timeout_s = timeout_s
        headers = {"Authorization": f"Bearer {token}"} if token else None
        # Entered as a context (websockets' intended use); `close()` leaves it.
        self._context = contextlib.ExitStack()
        self._ws: ClientConnection = self._context.enter_context(
            connect(url, additional_headers=headers, open_timeout=timeout_s)
        )
        self._ids = itertools.count(1)
        self._lock = threading.Lock()
        self._waiting: Dict[int, "queue.Queue[Json]"] = {}
        self._telemetry: "queue.Queue[Json]" = queue.Queue(maxsize=TELEMETRY_QUEUE_LEN)
        self._events: "queue.Queue[Json]" = queue.Queue(maxsize=EVENT_QUEUE_LEN)
        self._closed: Optional[str] = None
        self._reader = threading.Thread(target=self._read, name="thermode-client-reader", daemon=True)
        self._reader.start()

    # -- requests --------------------------------------------------------------------------------------------

    def touch(self, channel: int, material: Union[str, Json], object_temp_c: Optional[float] = None) -> Reply:
        """Touch `material` on `channel`: a library name (`status()`/`GET /api/materials`), or a dict of material
        properties (`conductivity_w_mk`, `density_kg_m3`, `specific_heat_j_kgk`, optional `thickness_m`, `name`).
        `object_temp_c`: the object's temperature [°C] (default: room temperature, 23)."""
        request: Json = {"type": "touch", "channel": channel}
        if isinstance(material, str):
            request["material"] = material
        else:
            request["properties"] = dict(material)
        if object_temp_c is not None:
            request["object_temp_c"] = object_temp_c
        return self.request(request)

    def release(self, channel: int) -> Reply:
        """Let go: `channel` renders air again."""
        return self.request({"type": "release", "channel": channel})

    def setpoint(self, channel: int, temp_c: float, rate_c_s: float) -> Reply:
        """Direct mode: the display of `channel` ramps to `temp_c` [°C] at `rate_c_s` [°C/s], through the safety
        envelope (its range and rate limit are `status()["limits"]`)."""
        return self.request({"type": "setpoint", "channel": channel, "temp_c": temp_c, "rate_c_s": rate_c_s})

    def clear_fault(self, channel: int) -> Reply:
        """Clear the latched safety fault of `channel` (refused with `device_fault` while its cause persists)."""
        return self.request({"type": "clear_fault", "channel": channel})

    def stop_all(self) -> Reply:
        """Release every channel and hold every drive at 0 A until that channel's next command."""
        return self.request({"type": "stop_all"})

    def marker(self, text: str, channel: Optional[int] = None) -> Reply:
        """Send an event marker (e.g. a trial start). The daemon answers with its loop `time_s` [s] when it took the
        marker (and `lsl_time_s` under `serve --lsl`, where the marker joins the LSL marker stream)."""
        message: Json = {"type": "marker", "text": text}
        if channel is not None:
            message["channel"] = channel
        return self.request(message)

    def program(self, channels: Mapping[int, Sequence[Json]]) -> Reply:
        """Run a stimulus program: `channels` maps each channel to its segments (at most 999), all channels starting
        on the same loop tick. A segment is `{"to_c": T, "rate_c_s": R}` (a ramp), `{"to_c": T}` (a step, as fast as
        the envelope allows) or `{"hold_s": D}` (a hold); a ramp or hold may add `"until": "response"` (a response on
        its channel ends it early and the program goes on). The reply's `fields` hold `start_tick`, `start_time_s`
        and `cutoff_c` (the display's limit a target was clipped to, else None) with every clipping in `cutoffs`.
        From now on this connection receives the program's events (see `wait_for_event`)."""
        message = {"type": "program", "channels": {str(c): [dict(s) for s in segs] for c, segs in channels.items()}}
        return self.request(message)

    def program_stop(self, channel: int) -> Reply:
        """End `channel`'s program; its set-point holds where the program left it."""
        return self.request({"type": "program_stop", "channel": channel})

    def response(self, channel: int, kind: str = "button", value: Optional[float] = None) -> Reply:
        """A participant's response on `channel`: `kind` "button", or "rating" with `value` 0–100. It takes effect on
        the loop's next tick: the reply's `tick`/`time_s` are that tick's, and its `fields` carry the plate's
        `sensor_c`, `plate_estimate_c` and `setpoint_c` at that tick (None where the device cannot measure) and the
        `until: response` segment it ended (`ended_segment`, else None)."""
        message: Json = {"type": "response", "channel": channel, "kind": kind}
        if value is not None:
            message["value"] = value
        return self.request(message)

    def wait_for_event(
        self,
        event: str,
        channel: Optional[int] = None,
        after_tick: Optional[int] = None,
        timeout_s: Optional[float] = None,
    ) -> Json:
        """Wait for the next program event named `event` ("segment_start", "response" or "program_end"), on
        `channel` if given, on a tick at or after `after_tick` if given; earlier events that do not match are
        skipped. Returns the event (with `tick`, `time_s`, `setpoint_c`, `sensor_c`, …). Raises
        `ThermodeError("timeout")` after `timeout_s` (default: the client's timeout). Events reach a connection that
        sent a program or a response, or that subscribes to telemetry."""
        wait_s = self.timeout_s if timeout_s is None else timeout_s
        deadline = time.monotonic() + wait_s
        while True:
            left_s = deadline - time.monotonic()
            try:
                message = self._events.get(timeout=max(0.0, left_s))
            except queue.Empty:
                raise ThermodeError("timeout", f"no `{event}` event within {wait_s} s") from None
            if "closed" in message:
                raise ThermodeError("connection_closed", message["closed"])
            if message.get("event") != event:
                continue
            if channel is not None and message.get("channel") != channel:
                continue
            if after_tick is not None and message.get("tick", -1) < after_tick:
                continue
            return message

    def wait_for_response(self, channel: Optional[int] = None, after_tick: Optional[int] = None,
                          timeout_s: Optional[float] = None) -> Json:
        """Wait for a participant's response (from any client: a button box, the dashboard, a script) on `channel`:
        the `response` event, with its `tick`, `time_s`, `kind`, `value`, and the plate's `sensor_c` and
        `setpoint_c` at that tick."""
        return self.wait_for_event("response", channel, after_tick, timeout_s)

    def wait_for_program_end(self, channel: Optional[int] = None, after_tick: Optional[int] = None,
                             timeout_s: Optional[float] = None) -> Json:
        """Wait until `channel`'s program has run its last segment (the `program_end` event)."""
        return self.wait_for_event("program_end", channel, after_tick, timeout_s)

    def subscribe(self, rate_hz: float, count: Optional[int] = None, timeout_s: Optional[float] = None) -> Iterator[Telemetry]:
        """Telemetry at `rate_hz` (0.01–100, at most the loop rate): yields frames until `count` have arrived (or
        forever), then unsubscribes. `timeout_s`: longest wait for one frame (default: the client's timeout)."""
        self._drain_telemetry()
        self.request({"type": "subscribe", "rate_hz": rate_hz})
        wait_s = self.timeout_s if timeout_s is None else timeout_s
        try:
            for _ in itertools.count() if count is None else range(count):
                try:
                    frame = self._telemetry.get(timeout=wait_s)
                except queue.Empty:
                    raise ThermodeError("timeout", f"no telemetry within {wait_s} s") from None
                if "closed" in frame:
                    raise ThermodeError("connection_closed", frame["closed"])
                yield Telemetry(time_s=frame["time_s"], tick=frame["tick"], channels=frame["channels"])
        finally:
            if self._closed is None:
                self.request({"type": "unsubscribe"})
                self._drain_telemetry()

    def status(self) -> Json:
        """`GET /api/status` of the same daemon (channels, limits, loop statistics, …) as a dict."""
        parts = urllib.parse.urlsplit(self.url)
        scheme = "https" if parts.scheme == "wss" else "http"
        url = urllib.parse.urlunsplit((scheme, parts.netloc, "/api/status", "", ""))
        request = urllib.request.Request(url)
        if self.token:
            request.add_header("Authorization", f"Bearer {self.token}")
        with urllib.request.urlopen(request, timeout=self.timeout_s) as response:
            return json.loads(response.read().decode("utf-8"))

    def request(self, message: Json) -> Reply:
        """Send one request (a dict with its `type`; the `id` is added) and wait for its reply. Raises
        `ThermodeError` on a refusal, a timeout or a closed connection."""
        if self._closed is not None:
            raise ThermodeError("connection_closed", self._closed)
        request_id = next(self._ids)
        slot: "queue.Queue[Json]" = queue.Queue(maxsize=1)
        with self._lock:
            self._waiting[request_id] = slot
        try:
            self._ws.send(json.dumps({**message, "id": request_id}))
            try:
                reply = slot.get(timeout=self.timeout_s)
            except queue.Empty:
                raise ThermodeError("timeout", f"no reply to `{message.get('type')}` within {self.timeout_s} s") from None
        except ConnectionClosed as closed:
            raise ThermodeError("connection_closed", str(closed)) from None
        finally:
            with self._lock:
                self._waiting.pop(request_id, None)
        if reply.get("type") == "error":
            raise ThermodeError(str(reply.get("code")), str(reply.get("message")))
        if "closed" in reply:
            raise ThermodeError("connection_closed", reply["closed"])
        return Reply(request=reply.get("request", ""), tick=reply.get("tick"), time_s=reply.get("time_s"), fields=reply)

    # -- connection ------------------------------------------------------------------------------------------

    def close(self) -> None:
        """Close the connection (the daemon releases this client's contacts after its grace period)."""
        self._context.close()
        self._reader.join(timeout=self.timeout_s)

    def __enter__(self) -> "Client":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _read(self) -> None:
        """The reader thread: dispatches replies by id and queues telemetry until the connection closes."""
        try:
            while True:
                message = json.loads(self._ws.recv())
                if message.get("type") == "telemetry":
                    self._queue_telemetry(message)
                    continue
                if message.get("type") == "program_event":
                    _put_dropping_oldest(self._events, message)
                    continue
                with self._lock:
                    slot = self._waiting.get(message.get("id"))
                if slot is not None:
                    slot.put(message)
        except ConnectionClosed as closed:
            self._closed = str(closed)
        finally:
            self._closed = self._closed or "the connection closed"
            with self._lock:
                for slot in self._waiting.values():
                    slot.put({"closed": self._closed})
            self._queue_telemetry({"closed": self._closed})
            _put_dropping_oldest(self._events, {"closed": self._closed})

    def _queue_telemetry(self, message: Json) -> None:
        """Queues a frame; when the queue is full the oldest frame goes."""
        _put_dropping_oldest(self._telemetry, message)

    def _drain_telemetry(self) -> None:
        while True:
            try:
                self._telemetry.get_nowait()
            except queue.Empty:
                return


def _put_dropping_oldest(into: "queue.Queue[Json]", message: Json) -> None:
    """Puts `message` in `into`; when it is full the oldest message goes."""
    while True:
        try:
            into.put_nowait(message)
            return
        except queue.Full:
            try:
                into.get_nowait()
            except queue.Empty:
                pass
