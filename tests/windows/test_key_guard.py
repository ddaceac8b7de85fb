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


def test_qt_repeat_flag_of_a_key_the_window_system_said_was_up_is_a_press() -> None:
    # Qt's xcb backend flags the next press of the key it last saw repeating when that key's
    # release went to another window. The X server said W was up when the console got the
    # keyboard: W's press is new, whatever Qt says.
    down: set[str] = set()
    guard = KeyGuard(lambda: frozenset(down))
    guard.activated()
    down.add("W")
    assert guard.press("W", T0, qt_repeat=True) is Verdict.PRESS
    assert guard.press("W", T0 + 660, qt_repeat=True) is Verdict.REPEAT  # now it is down
    down.discard("W")
    assert guard.release("W", T0 + 700, qt_repeat=False, held=True)
    # Without the window system's answer, Qt's flag is all there is: a key held elsewhere.
    blind = KeyGuard(None)
    blind.activated()
    assert blind.press("W", T0, qt_repeat=True) is Verdict.BLOCKED
    # Nor when the server did not answer at activation.
    silent = KeyGuard(lambda: None)
    silent.activated()
    assert silent.press("W", T0, qt_repeat=True) is Verdict.BLOCKED


def test_a_release_and_a_new_press_before_the_console_asked_are_both_real() -> None:
    # A busy GUI thread handles W's release after W went down again: the X server says W is
    # down, but the press that follows carries another server time - not a repeat pair. The
    # release counts (W blocked since before is unblocked) and the press drives.
    down: set[str] = {"W"}
    guard = KeyGuard(lambda: frozenset(down))
    guard.activated()
    assert guard.press("W", T0, qt_repeat=False) is Verdict.BLOCKED
    assert not guard.release("W", T0 + 100, qt_repeat=False, held=False)  # W down again
    assert guard.press("W", T0 + 103, qt_repeat=False) is Verdict.PRESS
    assert guard.blocked == frozenset()
    # The same with a key the console holds: the new press goes on driving.
    assert not guard.release("W", T0 + 900, qt_repeat=False, held=True)
    assert guard.press("W", T0 + 905, qt_repeat=False) is Verdict.PRESS
    # A true repeat pair (one server time) is still a repeat.
    assert not guard.release("W", T0 + 1565, qt_repeat=False, held=True)
    assert guard.press("W", T0 + 1565, qt_repeat=False) is Verdict.REPEAT
