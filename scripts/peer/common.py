"""What the peer scripts share: timing a whole process and their argument parser's start. (The peers' physics is
written independently in each script, on purpose: each is a check of thermode, not of the other.)"""

import argparse
import subprocess
import time


def timed(cmd):
    """Seconds of wall time of one whole run of `cmd` (its output discarded)."""
    start = time.perf_counter()
    subprocess.run(cmd, check=True, capture_output=True)
    return time.perf_counter() - start


def parser(doc):
    """An argument parser that prints the script's module doc as its help."""
    return argparse.ArgumentParser(description=doc, formatter_class=argparse.RawDescriptionHelpFormatter)
