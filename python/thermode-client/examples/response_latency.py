#!/usr/bin/env python3
"""Response-to-stop latency of a running `thermode serve`: N method-of-limits ramps on one connection, each stopped by
a `response`; each response is timed from send to its reply, which the daemon sends after the tick that applied it
(the ramp's last set-point change is on or before that tick), so the figure bounds "request sent -> ramp stopped"
from above. Requests are paced below the API's per-connection rate limit (50 requests/s); prints p50, p99 and max in
ms, and checks that every response ended its ramp.

    thermode serve --rate 1000 &
    python3 python/thermode-client/examples/response_latency.py --url ws://127.0.0.1:8765/api/ws --count 500
"""

import argparse
import statistics
import time

from thermode_client import Client


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--url", default="ws://127.0.0.1:8765/api/ws")
    parser.add_argument("--token", default=None)
    parser.add_argument("--count", type=int, default=500)
    parser.add_argument("--channel", type=int, default=0)
    parser.add_argument("--interval-s", type=float, default=0.025, help="time between requests (rate limit: 50/s)")
    args = parser.parse_args()
    # Back to 32 °C (a step), then down at 1 °C/s until the response, then hold.
    ramp = [{"to_c": 32}, {"to_c": 20, "rate_c_s": 1, "until": "response"}, {"hold_s": 60}]
    latencies_ms = []
    with Client(args.url, token=args.token) as display:
        for _ in range(args.count):
            display.program({args.channel: ramp})
            time.sleep(args.interval_s)
            started = time.perf_counter()
            reply = display.response(args.channel)
            latencies_ms.append((time.perf_counter() - started) * 1e3)
            if reply.fields.get("ended_segment") != 1:
                raise SystemExit(f"a response did not end the ramp: {reply.fields}")
            time.sleep(max(0.0, args.interval_s - (time.perf_counter() - started)))
        display.release(args.channel)
    latencies_ms.sort()
    p99 = latencies_ms[min(len(latencies_ms) - 1, int(0.99 * len(latencies_ms)))]
    print(
        f"{len(latencies_ms)} responses (send -> reply after the stopping tick): p50 "
        f"{statistics.median(latencies_ms):.2f} ms, p99 {p99:.2f} ms, max {latencies_ms[-1]:.2f} ms"
    )


if __name__ == "__main__":
    main()
