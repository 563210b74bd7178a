#!/usr/bin/env python3
"""Touch-to-reply latency of a running `thermode serve`: N touch requests on one connection, each timed from send
to reply, paced below the API's per-connection rate limit (50 requests/s); prints p50, p99 and max in ms.

    thermode serve --rate 1000 &
    python3 python/thermode-client/examples/latency.py --url ws://127.0.0.1:8765/api/ws --count 1000
"""

import argparse
import statistics
import time

from thermode_client import Client


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--url", default="ws://127.0.0.1:8765/api/ws")
    parser.add_argument("--token", default=None)
    parser.add_argument("--count", type=int, default=1000)
    parser.add_argument("--channel", type=int, default=1)
    parser.add_argument("--interval-s", type=float, default=0.025, help="time between requests (rate limit: 50/s)")
    args = parser.parse_args()
    materials = ["aluminium", "wood"]
    latencies_ms = []
    with Client(args.url, token=args.token) as display:
        for k in range(args.count):
            started = time.perf_counter()
            display.touch(args.channel, materials[k % 2])
            latencies_ms.append((time.perf_counter() - started) * 1e3)
            time.sleep(max(0.0, args.interval_s - (time.perf_counter() - started)))
        display.release(args.channel)
    latencies_ms.sort()
    p99 = latencies_ms[min(len(latencies_ms) - 1, int(0.99 * len(latencies_ms)))]
    print(
        f"{len(latencies_ms)} touches: p50 {statistics.median(latencies_ms):.2f} ms, p99 {p99:.2f} ms, "
        f"max {latencies_ms[-1]:.2f} ms"
    )


if __name__ == "__main__":
    main()
