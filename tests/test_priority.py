"""The console's scheduling priority (ocu.priority): asked for first, inherited by threads,
refused without the permission, and not given to the simulator that stands in for the robot.

Each case runs in a child process: a nice value, once lowered, cannot be raised back by a
process without the permission, and the test process must keep its own.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap

from ocu.priority import current_nice

CHILD_TIMEOUT_S = 60.0


def run_child(code: str) -> dict[str, object]:
    """Run `code` in a fresh interpreter; it prints one JSON object as its last line."""
    result = subprocess.run(
        [sys.executable, "-c", textwrap.dedent(code)],
        capture_output=True,
        text=True,
        timeout=CHILD_TIMEOUT_S,
        check=False,
    )
    assert result.returncode == 0, result.stderr
    return dict(json.loads(result.stdout.strip().splitlines()[-1]))


def privileged() -> bool:
    """Whether this process may lower its nice value at all (root, or an RLIMIT_NICE)."""
    from ocu.priority import allowed_nice

    return os.geteuid() == 0 or allowed_nice() < current_nice()


def test_threads_started_after_inherit_the_priority_asked_for() -> None:
    got = run_child(
        """
        import json, os, threading
        from ocu.priority import raise_priority, current_nice
        before = current_nice()
        priority = raise_priority(before - 5 if before - 5 >= -20 else -20)
        seen = {}
        thread = threading.Thread(target=lambda: seen.update(nice=current_nice()))
        thread.start(); thread.join()
        print(json.dumps({"before": before, "asked": priority.asked, "got": priority.got,
                          "thread": seen["nice"], "text": priority.text}))
        """
    )
    if privileged():
        assert got["got"] == got["asked"]
        assert got["text"] == f"nice {got['asked']}"
    else:
        assert got["got"] == got["before"]
        assert "not permitted" in str(got["text"])
    # Whatever it got, the thread started after has the same.
    assert got["thread"] == got["got"]


def test_without_the_permission_it_takes_what_rlimit_nice_allows_and_says_so() -> None:
    # As root, drop to "nobody" first (allowed then only by RLIMIT_NICE, as for any user).
    got = run_child(
        """
        import json, os, resource
        from ocu.priority import raise_priority, current_nice
        soft, hard = resource.getrlimit(resource.RLIMIT_NICE)
        if os.geteuid() == 0:
            # nice down to -5 where the hard limit allows it (not in every container)
            resource.setrlimit(resource.RLIMIT_NICE, (min(25, hard), hard))
            os.setgid(65534); os.setuid(65534)
        before = current_nice()
        allowed = 20 - resource.getrlimit(resource.RLIMIT_NICE)[0]
        asked = max(-20, before - 5)  # lower than now (this process may run raised)
        priority = raise_priority(asked)
        print(json.dumps({"before": before, "allowed": max(allowed, asked),
                          "got": priority.got, "text": priority.text}))
        """
    )
    if got["allowed"] < got["before"]:  # type: ignore[operator]
        assert got["got"] == got["allowed"]
        assert got["text"] == f"nice {got['allowed']} (RLIMIT_NICE allows {got['allowed']})"
    else:
        assert got["got"] == got["before"]
        assert "not permitted: needs CAP_SYS_NICE" in str(got["text"])


def test_the_built_in_simulator_runs_at_the_default_priority_beside_a_raised_console() -> None:
    got = run_child(
        """
        import json, os
        from ocu.priority import raise_priority, current_nice
        from ocu.sim.launcher import SimulatorProcess
        console = raise_priority(-5).got
        with SimulatorProcess(None, ["--log-level", "WARNING"]) as sim:
            pid = sim.process.pid
            # The launcher's "nice" exec()s the simulator: the same pid, once it reports.
            simulator = os.getpriority(os.PRIO_PROCESS, pid)
        print(json.dumps({"console": console, "simulator": simulator}))
        """
    )
    if got["console"] < 0:  # type: ignore[operator]
        assert got["simulator"] == 0
    else:
        assert got["simulator"] == got["console"]


def test_a_bad_nice_value_is_refused_naming_where_it_came_from() -> None:
    for argv, env, message in (
        (["--nice", "99"], {}, "--nice: 99 is outside -20..19"),
        ([], {"OCU_NICE": "fast"}, "$OCU_NICE: not a whole number: 'fast'"),
    ):
        result = subprocess.run(
            [sys.executable, "-m", "ocu", *argv, "--quit-after", "0"],
            capture_output=True,
            text=True,
            timeout=CHILD_TIMEOUT_S,
            env={**os.environ, **env},
            check=False,
        )
        assert result.returncode == 2
        assert message in result.stderr
