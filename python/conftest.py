"""Fixtures of the Python packages' tests (`thermode-client`, `psychopy-thermode`): `thermode serve` on the simulated
display on free ports, with its own state directory, stopped afterwards. The packages are imported from their
`src` folders, so the tests need no installation.

The binary: `$THERMODE_BIN`, else the repository's `target/debug/thermode`, else `target/release/thermode`.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Iterator

import pytest

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
for package in ("thermode-client", "psychopy-thermode"):
    sys.path.insert(0, str(HERE / package / "src"))


def thermode_binary() -> str:
    candidates = [os.environ.get("THERMODE_BIN", "")]
    candidates += [str(REPO / "target" / kind / "thermode") for kind in ("debug", "release")]
    for candidate in candidates:
        if candidate and os.access(candidate, os.X_OK):
            return candidate
    pytest.fail("no thermode binary: build it (`cargo build -p thermode`) or set THERMODE_BIN")


class Daemon:
    """A running `thermode serve`: its WebSocket URL and process."""

    def __init__(self, *extra: str) -> None:
        self.state = tempfile.TemporaryDirectory(prefix="thermode-state-")
        args = [thermode_binary(), "serve", "--port", "0", "--no-osc", "--rate", "100", "--state-dir", self.state.name]
        args += list(extra)
        self.process = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        self.banner = []
        assert self.process.stdout is not None
        for line in self.process.stdout:
            self.banner.append(line)
            found = re.search(r"ws://[^\s]+/api/ws", line)
            if found:
                self.url = found.group(0)
                break
        else:
            raise RuntimeError("thermode serve printed no WebSocket address:\n" + "".join(self.banner))

    def stop(self) -> None:
        self.process.terminate()
        try:
            self.process.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait()
        self.state.cleanup()


@pytest.fixture(scope="session")
def daemon() -> Iterator[Daemon]:
    running = Daemon()
    yield running
    running.stop()


@pytest.fixture(scope="session")
def token_daemon() -> Iterator[Daemon]:
    running = Daemon("--token", "s3cret-token")
    yield running
    running.stop()

