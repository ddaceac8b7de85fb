"""A console without Qt driving a robot, run as a child process the tests can freeze or signal.

    python -m tests.link.drive_child HOST PORT MODE

MODE "hold": a slider held at a steady speed; "path": the speed changes every control tick
(as path following does); "crash": with the console's exit guard installed (as `ocu` has it),
the main thread raises once stdin has a line, without stopping the console. Prints "driving"
once the first motion command is set, then runs until stdin closes.
"""

from __future__ import annotations

import functools
import sys
import threading

from ocu.console.model import ConsoleModel
from ocu.hardware.engineer import engineer_component
from ocu.headless import HeadlessConsole
from ocu.link.guard import ExitGuard
from ocu.link.live import UdpLink
from ocu.profile import load_profile

TICK_S = 0.05


def main() -> None:
    host, port, mode = sys.argv[1], int(sys.argv[2]), sys.argv[3]
    profile = load_profile()
    link = UdpLink(profile, (host, port))
    model = ConsoleModel(profile)
    console = HeadlessConsole(model, engineer_component(link))
    if mode == "crash":
        ExitGuard().install()
    console.start()
    done = threading.Event()

    def wait_for_eof() -> None:
        sys.stdin.read()
        done.set()

    threading.Thread(target=wait_for_eof, daemon=True).start()
    console.call(lambda: model.set_velocity("neck", 0.3))
    print("driving", flush=True)
    if mode == "crash":
        sys.stdin.readline()
        raise RuntimeError("the console failed")
    step = 0
    while not done.wait(TICK_S):
        if mode == "path":
            step += 1
            speed = 0.2 + 0.1 * (step % 2)
            console.call(functools.partial(model.set_velocity, "neck", speed))
    console.stop()


if __name__ == "__main__":
    main()
