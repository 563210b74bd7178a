#!/usr/bin/env python3
"""A small material-identification experiment (the paper's task) with psychopy-thermode.

Each trial shows one material on the index finger for a few seconds, then asks which material it was. With
PsychoPy installed the question is a window with keyboard answers; without it, the console. Answers are written
to a CSV. Start a daemon first:

    thermode serve &
    python3 python/psychopy-thermode/examples/material_identification.py --participant P01 --out answers.csv
"""

import argparse
import csv
import random
import time

from psychopy_thermode import ThermodeDevice

MATERIALS = ["aluminium", "steel", "stone", "wood", "rubber"]
KEYS = {str(k + 1): name for k, name in enumerate(MATERIALS)}


def ask(prompt: str) -> str:
    """The participant's answer: a PsychoPy window if available, else the console."""
    try:
        from psychopy import event, visual  # noqa: PLC0415 (optional dependency)
    except ImportError:
        return input(prompt + " ")
    window = visual.Window(size=(800, 400), color="black")
    visual.TextStim(window, text=prompt, color="white", height=0.08).draw()
    window.flip()
    key = event.waitKeys(keyList=list(KEYS))[0]
    window.close()
    return key


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--url", default="ws://127.0.0.1:8765/api/ws")
    parser.add_argument("--participant", required=True)
    parser.add_argument("--out", default="answers.csv")
    parser.add_argument("--present-s", type=float, default=5.0)
    parser.add_argument("--rest-s", type=float, default=10.0)
    parser.add_argument("--seed", type=int, default=1)
    args = parser.parse_args()
    trials = MATERIALS * 2
    random.Random(args.seed).shuffle(trials)
    prompt = "Which material? " + ", ".join(f"{k} {name}" for k, name in KEYS.items())
    device = ThermodeDevice(url=args.url, channel=1)
    try:
        with open(args.out, "w", newline="") as out:
            writer = csv.writer(out)
            writer.writerow(["participant", "trial", "material", "answer", "finger_start_c"])
            for trial, material in enumerate(trials, start=1):
                finger_c = device.finger_temperature_c()
                device.touch(material)
                time.sleep(args.present_s)
                device.release()
                answer = KEYS.get(ask(prompt).strip(), "")
                writer.writerow([args.participant, trial, material, answer, f"{finger_c:.2f}"])
                out.flush()
                time.sleep(args.rest_s)
    finally:
        device.stop()
        device.close()


if __name__ == "__main__":
    main()
