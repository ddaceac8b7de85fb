"""A console without Qt driving a robot, run as a child process the tests can freeze or signal.

    python -m tests.link.drive_child HOST PORT MODE

MODE "hold": a slider held at a steady speed; "path": the speed changes every control tick
(as path following does). Prints "driving" once the first motion command is set, then runs
until stdin closes.
"""

from __future__ import annotations

import sys
import threading

from ocu.console.model import ConsoleModel
from ocu.headless import HeadlessConsole
from ocu.link.live import UdpLink
from ocu.profile import load_profile

TICK_S = 0.05


def main() -> None:
    host, port, mode = sys.argv[1], int(sys.argv[2]), sys.argv[3]
    profile = load_profile()
    link = UdpLink(profile, (host, port))
    model = ConsoleModel(profile)
    console = HeadlessConsole(model, link)
    console.start()
    done = threading.Event()
    threading.Thread(target=lambda: (sys.stdin.read(), done.set()), daemon=True).start()
    console.call(lambda: model.set_velocity("neck", 0.3))
    print("driving", flush=True)
    step = 0
    while not done.wait(TICK_S):
        if mode == "path":
            step += 1
            speed = 0.2 + 0.1 * (step % 2)
            console.call(lambda speed=speed: model.set_velocity("neck", speed))
    console.stop()


if __name__ == "__main__":
    main()
