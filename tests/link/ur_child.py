"""A UR link driving an arm, run as a child process the tests can kill.

    python -m tests.link.ur_child HOST PRIMARY SECONDARY REALTIME JOINT SPEED

Connects, sets JOINT to SPEED (rad/s) once the link is connected, prints "moving", then
heartbeats until stdin closes (or the test kills it with SIGKILL).
"""

from __future__ import annotations

import sys
import threading

from ocu.link.ur import UrLink
from ocu.profile.ur import load_ur_profile
from ocu.records import Command, LinkState

HEARTBEAT_S = 0.05
CONNECT_DEADLINE_S = 10.0


def main() -> None:
    host = sys.argv[1]
    ports = (int(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4]))
    joint, speed = sys.argv[5], float(sys.argv[6])
    link = UrLink(load_ur_profile("ur5e"), host, ports=ports)
    connected = threading.Event()
    link.subscribe(
        lambda event: (
            connected.set() if getattr(event, "state", None) is LinkState.CONNECTED else None
        )
    )
    link.start()
    if not connected.wait(CONNECT_DEADLINE_S):
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
