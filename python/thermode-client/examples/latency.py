#!/usr/bin/env python3
"""Latency of a running `thermode serve`, paced below the API's per-connection rate limit (50 requests/s); prints p50,
p99 and max in ms.

- `--mode touch` (default): N touch requests on one connection, each timed from send to reply.
- `--mode response`: N method-of-limits ramps (a step to 32 °C, then down at 1 °C/s `until: response`), each ended by
  a `response` timed from send to its reply; the daemon replies after the tick that applied the response (the ramp's
  last set-point change is on or before it), so the figure bounds "request sent -> ramp stopped" from above. Every
  response is checked to have ended its ramp.

    thermode serve --rate 1000 &
    python3 python/thermode-client/examples/latency.py --url ws://127.0.0.1:8765/api/ws --count 1000
    python3 python/thermode-client/examples/latency.py --mode response --channel 0 --count 1000
"""

import argparse
import statistics
import time

from thermode_client import Client

#: The response mode's program: back to 32 °C, down at 1 °C/s until the response, then hold.
LIMITS_RAMP = [{"to_c": 32}, {"to_c": 20, "rate_c_s": 1, "until": "response"}, {"hold_s": 60}]


def timed_touch(display: Client, channel: int, k: int) -> float:
    """One touch, alternating aluminium and wood: its send-to-reply time [s]."""
    started = time.perf_counter()
    display.touch(channel, ["aluminium", "wood"][k % 2])
    return time.perf_counter() - started


def timed_response(display: Client, channel: int, pause_s: float) -> float:
    """A limits ramp, then after `pause_s` a response: its send-to-reply time [s]."""
    display.program({channel: LIMITS_RAMP})
    time.sleep(pause_s)
    started = time.perf_counter()
    reply = display.response(channel)
    elapsed_s = time.perf_counter() - started
    if reply.fields.get("ended_segment") != 1:
        raise SystemExit(f"a response did not end the ramp: {reply.fields}")
    return elapsed_s


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--url", default="ws://127.0.0.1:8765/api/ws")
    parser.add_argument("--token", default=None)
    parser.add_argument("--mode", choices=["touch", "response"], default="touch")
    parser.add_argument("--count", type=int, default=1000)
    parser.add_argument("--channel", type=int, default=1)
    parser.add_argument("--interval-s", type=float, default=0.025, help="time between requests (rate limit: 50/s)")
    args = parser.parse_args()
    latencies_ms = []
    # A response run makes two requests (the program and the response).
    per_run_s = args.interval_s * (1 if args.mode == "touch" else 2)
    with Client(args.url, token=args.token) as display:
        for k in range(args.count):
            started = time.perf_counter()
            if args.mode == "touch":
                latencies_ms.append(timed_touch(display, args.channel, k) * 1e3)
            else:
                latencies_ms.append(timed_response(display, args.channel, args.interval_s) * 1e3)
            time.sleep(max(0.0, per_run_s - (time.perf_counter() - started)))
        display.release(args.channel)
    latencies_ms.sort()
    p99 = latencies_ms[min(len(latencies_ms) - 1, int(0.99 * len(latencies_ms)))]
    what = "touches" if args.mode == "touch" else "responses (send -> reply after the stopping tick)"
    print(
        f"{len(latencies_ms)} {what}: p50 {statistics.median(latencies_ms):.2f} ms, p99 {p99:.2f} ms, "
        f"max {latencies_ms[-1]:.2f} ms"
    )


if __name__ == "__main__":
    main()
