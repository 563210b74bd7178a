"""thermode-client: the Python client of `thermode serve`'s contact API (`docs/api.md` in the thermode repository).

`Client` is one blocking WebSocket connection with `touch`, `release`, `setpoint`, `clear_fault`, `stop_all`,
`subscribe` (telemetry) and `status`; refusals raise `ThermodeError` with the daemon's error code.
"""

from .client import DEFAULT_TIMEOUT_S, Client, Reply, Telemetry, ThermodeError

__all__ = ["Client", "Reply", "Telemetry", "ThermodeError", "DEFAULT_TIMEOUT_S"]
__version__ = "0.1.0"
