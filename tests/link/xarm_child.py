"""An xArm link jogging a joint, run as a child process the tests can kill.

    python -m tests.link.xarm_child PORT JOINT SPEED

Opens PORT, sets JOINT to SPEED (rad/s) once the link is connected and has read the servos,
prints "moving", then heartbeats until stdin closes (or the test kills it with SIGKILL).
"""

from __future__ import annotations

import sys
import threading

from ocu.link.xarm import XarmLink
from ocu.profile.xarm import load_xarm_profile
from ocu.records import Command, LinkState, TelemetryFrame

HEARTBEAT_S = 0.05
CONNECT_DEADLINE_S = 10.0


def main() -> None:
    port, joint, speed = sys.argv[1], sys.argv[2], float(sys.argv[3])
    link = XarmLink(load_xarm_profile("xarm1s"), port)
    connected = threading.Event()
    read = threading.Event()

    def on_event(event: object) -> None:
        if getattr(event, "state", None) is LinkState.CONNECTED:
            connected.set()
        if isinstance(event, TelemetryFrame):
            read.set()

    link.subscribe(on_event)
    link.start()
    if not (connected.wait(CONNECT_DEADLINE_S) and read.wait(CONNECT_DEADLINE_S)):
        print("not connected", flush=True)
        link.shutdown()
        sys.exit(1)
    link.heartbeat()
    link.set_command(Command({joint: speed}))
    print("moving", flush=True)
    done = threading.Event()

    def wait_for_eof() -> None:
        sys.stdin.read()
        done.set()

    threading.Thread(target=wait_for_eof, daemon=True).start()
    while not done.wait(HEARTBEAT_S):
        link.heartbeat()
    link.shutdown()


if __name__ == "__main__":
    main()
