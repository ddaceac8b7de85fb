"""KeyGuard (no Qt): real presses and releases told from auto-repeat and keys held before."""

from __future__ import annotations

from ocu.windows.key_filter import KeyGuard, Verdict

T0 = 1_000_000  # an X server time (ms)


def test_key_guard_uses_the_window_systems_key_state() -> None:
    down: set[str] = {"W", "Q"}
    guard = KeyGuard(lambda: frozenset(down))
    guard.activated()  # W and Q were pressed in another window
    assert guard.blocked == {"W", "Q"}
    assert guard.press("W", T0, qt_repeat=False) is Verdict.BLOCKED
    # An X11 repeat pair's release: the server says W is still down.
    assert not guard.release("W", T0 + 40, qt_repeat=False, held=False)
    assert guard.press("W", T0 + 40, qt_repeat=False) is Verdict.BLOCKED
    down.discard("W")
    assert guard.release("W", T0 + 50, qt_repeat=False, held=False)
    assert guard.press("W", T0 + 300, qt_repeat=False) is Verdict.PRESS
    down.add("W")
    assert not guard.release("W", T0 + 960, qt_repeat=False, held=True)  # no stutter
    assert guard.press("W", T0 + 960, qt_repeat=False) is Verdict.REPEAT
    guard.deactivated()
    assert guard.blocked == frozenset()
    assert guard.down == frozenset()
    # Without the window system's answer: a pair whose release stopped our held key is a
    # repeat of it (press again); one that stopped nothing blocks the key.
    blind = KeyGuard(None)
    blind.activated()
    assert blind.press("E", T0, qt_repeat=False) is Verdict.PRESS
    assert blind.release("E", T0 + 660, qt_repeat=False, held=True)
    assert blind.press("E", T0 + 660, qt_repeat=False) is Verdict.RESUME
    assert blind.release("E", T0 + 700, qt_repeat=False, held=False)  # after Space
    assert blind.press("E", T0 + 700, qt_repeat=False) is Verdict.BLOCKED
