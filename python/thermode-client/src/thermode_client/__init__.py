"""thermode-client: the Python client of `thermode serve`'s contact API (`docs/api.md` in the thermode repository).

`Client` is one blocking WebSocket connection with `touch`, `release`, `setpoint`, `clear_fault`, `stop_all`,
`program`, `program_stop`, `response`, `wait_for_response`, `wait_for_program_end`, `wait_for_event`, `subscribe`
(telemetry) and `status`; refusals raise `ThermodeError` with the daemon's error code.
"""

from .client import DEFAULT_TIMEOUT_S, MAX_SEGMENTS, Client, Reply, Telemetry, ThermodeError

__all__ = ["Client", "Reply", "Telemetry", "ThermodeError", "DEFAULT_TIMEOUT_S", "MAX_SEGMENTS"]
__version__ = "0.1.0"
