"""The input mux: the table the code reads (ocu/control/mux.md), its checks, and a model run
by it - a changed table changes what the model does, and a new source is one small class plus
a registration line and a row."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from ocu.console.model import ConsoleModel, Source
from ocu.control.mux import OPERATOR, TABLE_PATH, InputMux, MuxError
from ocu.profile import RobotProfile

DOCS = Path(__file__).resolve().parents[2] / "docs" / "console.md"
SHIPPED = TABLE_PATH.read_text(encoding="utf-8")


class Clock:
    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


def table_rows(text: str) -> list[str]:
    return [line.strip() for line in text.splitlines() if line.strip().startswith("|")]


def with_cell(source: str, column: str, value: str, text: str = SHIPPED) -> str:
    """The shipped table with one cell changed."""
    rows = table_rows(text)
    header = [c.strip() for c in rows[0].strip("|").split("|")]
    index = header.index(column)
    out = []
    for row in rows:
        cells = [c.strip() for c in row.strip("|").split("|")]
        if cells[0] == source:
            cells[index] = value
        out.append("| " + " | ".join(cells) + " |")
    return "\n".join(out) + "\n"


def test_the_docs_show_the_table_the_code_reads() -> None:
    docs = DOCS.read_text(encoding="utf-8")
    block = re.search(r"<!-- mux table -->\n(.*?)<!-- /mux table -->", docs, re.S)
    assert block is not None, "docs/console.md has no mux table block"
    assert table_rows(block.group(1)) == table_rows(SHIPPED)


def test_the_shipped_rules() -> None:
    mux = InputMux.shipped()
    built_in = [Source.SLIDER, Source.TEXT, Source.HOTKEY, Source.SWITCH, Source.GAMEPAD]
    built_in += [Source.POSITION, Source.ARM, Source.ASSIST, Source.TRACK, Source.ROS]
    assert mux.sources == (*(s.value for s in built_in), "live")
    # The latest manual input wins; automatic sources and planners never take a channel
    # from the operator; a planner yields to everything, an automatic source to no planner.
    assert mux.may_take("slider", "hotkey")
    assert mux.may_take("gamepad", "slider")
    assert mux.may_take("hotkey", "position")
    assert mux.may_take("switch", "ros")
    assert not mux.may_take("ros", "position")
    assert not mux.may_take("ros", "slider")
    assert not mux.may_take("assist", "hotkey")
    assert mux.may_take("assist", "ros")
    assert not mux.may_take("position", "arm")
    assert mux.may_take("ros", "none")
    assert mux.may_take("ros", "ros")
    never = lambda source, condition: False  # noqa: E731
    always = lambda source, condition: True  # noqa: E731
    assert mux.stopped_by("e-stop", always) == list(mux.sources)
    assert mux.stopped_by("LINK LOST", always) == list(mux.sources)
    assert mux.stopped_by("robot stop", always) == list(mux.sources)
    assert "ros" not in mux.stopped_by("focus lost", never)
    assert "gamepad" in mux.stopped_by("focus lost", never)
    assert "gamepad" not in mux.stopped_by("focus lost", always)
    assert mux.stopped_by(OPERATOR, always) == ["assist", "track", "ros", "live"]
    assert mux.stopped_by(OPERATOR, never) == ["arm", "assist", "track", "ros", "live"]
    # A remote client (ocu.live, --live-control) stops for every lock and any operator input.
    assert "live" in mux.stopped_by("focus lost", always)
    assert "live" in mux.stopped_by("GUI silent", always)
    assert mux.timed() == [("live", 0.6)]
    assert not mux.may_take("live", "ros")
    assert not mux.may_take("live", "hotkey")
    assert mux.stopped_by("GUI silent", never) == [
        "slider", "text", "hotkey", "switch", "arm", "assist", "track", "live"
    ]  # fmt: skip
    assert mux.fed_by("gui") == ["slider", "text", "hotkey", "switch"]


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("no table here", "no table"),
        (SHIPPED.replace("| timeout |", "| deadline |", 1), "the columns must be"),
        (with_cell("ros", "kind", "robot"), r"source 'ros', column kind: one of manual"),
        (with_cell("ros", "priority", "high"), r"source 'ros', column priority: a whole"),
        (with_cell("ros", "e-stop", "keeps"), r"source 'ros', column e-stop: every source"),
        (with_cell("arm", "LINK LOST", "keeps if a move"), r"'arm', column LINK LOST: every"),
        (with_cell("ros", "focus lost", "keeps if sunny"), r"'ros', column focus lost: stops,"),
        (with_cell("ros", OPERATOR, "wins"), r"'ros', column any operator input: wins for a"),
        (with_cell("slider", OPERATOR, "stops"), r"'slider', column any operator input"),
        (with_cell("ros", "timeout", "-1"), r"'ros', column timeout: gui, pad, ros, - or"),
        (with_cell("ros", "timeout", "nan"), r"'ros', column timeout"),
        (
            SHIPPED + "| ros | planner | 1 | ros | stops | keeps | keeps | stops | stops | stops |",
            "second",
        ),
        (with_cell("ros", "robot stop", "keeps"), r"'ros', column robot stop: every source"),
        (SHIPPED + "| x | planner | 1 | ros | stops |\n", r"table row 12: 5 cells"),
    ],
)
def test_a_bad_table_is_refused_naming_the_file_row_and_column(text: str, message: str) -> None:
    with pytest.raises(MuxError, match=message) as caught:
        InputMux.from_text(text, "my-mux.md")
    assert str(caught.value).startswith("my-mux.md")


def test_the_model_does_what_the_table_says(profile: RobotProfile) -> None:
    # Shipped: losing focus keeps a planner going.
    model = ConsoleModel(profile)
    model.set_external_velocities({"waist": 0.1})
    model.halt("console lost focus", lock="focus lost")
    assert model.velocities() == {"waist": 0.1}
    # The same table with the planner stopping for focus loss: the model stops it.
    strict = InputMux.from_text(with_cell("ros", "focus lost", "stops"), "strict.md")
    model = ConsoleModel(profile, mux=strict)
    model.set_external_velocities({"waist": 0.1})
    model.halt("console lost focus", lock="focus lost")
    assert model.velocities() == {}
    # And with a planner above the operator's hands, a slider no longer takes its channel.
    bossy = InputMux.from_text(with_cell("ros", "priority", "9"), "bossy.md")
    model = ConsoleModel(profile, mux=bossy)
    model.set_velocity("waist", 0.2)
    assert model.set_external_velocities({"waist": 0.1, "elbow": 0.1}) == {
        "waist": 0.1,
        "elbow": 0.1,
    }
    assert model.channel("waist").source is Source.ROS


def test_a_silent_gui_stops_what_it_feeds_and_nothing_else(profile: RobotProfile) -> None:
    model = ConsoleModel(profile)
    model.set_target("neck", 0.3)
    model.hotkey_down("W", "drive_linear", 1)
    model.set_velocity("elbow", 0.2)
    model.set_external_velocities({"waist": 0.1})  # after the operator's input, or it stops
    assert model.halt("GUI thread silent for 0.45 s", lock="GUI silent")
    assert model.held_keys == frozenset()
    assert model.channel("drive_linear").velocity == 0.0
    assert model.channel("elbow").velocity == 0.0
    assert model.channel("waist").source is Source.ROS
    assert model.targets == {"neck": 0.3}


# ---- a new source: one class, one registration line, one row ------------------------------

REMOTE_ROW = "| remote | planner | 1 | 0.3 | stops | keeps | stops | stops | stops | stops |\n"


class RemoteTeleop:
    """What a remote client's teleop (issue 24's Foxglove panel) needs of the model."""

    source = Source.define("remote")

    def __init__(self, model: ConsoleModel) -> None:
        self.model = model
        self.stops: list[str] = []
        model.mux.register(self.source.value, self.stop)  # the registration line

    def twist(self, linear_m_s: float, angular_rad_s: float) -> dict[str, float]:
        return self.model.set_source_velocities(
            self.source, {"drive_linear": linear_m_s, "drive_turn": angular_rad_s}
        )

    def stop(self, reason: str) -> None:
        self.stops.append(reason)
        self.model.clear_source(self.source)


def test_a_new_source_plugs_in_with_a_row_and_a_registration(profile: RobotProfile) -> None:
    clock = Clock()
    mux = InputMux.from_text(SHIPPED + REMOTE_ROW, "mux+remote.md")
    model = ConsoleModel(profile, clock=clock, mux=mux)
    remote = RemoteTeleop(model)
    assert remote.twist(0.2, 0.0) == {"drive_linear": 0.2, "drive_turn": 0.0}
    assert model.channel("drive_linear").source is remote.source
    # Its timeout: 0.3 s after its last input it stops by itself.
    clock.now += 0.25
    model.update()
    assert model.velocities() == {"drive_linear": 0.2}
    clock.now += 0.1
    model.update()
    assert model.velocities() == {}
    # Any operator input stops it, and it cannot take the operator's channel.
    remote.twist(0.2, 0.0)
    model.hotkey_down("Y", "shoulder", 1)
    assert remote.stops == ["operator took over"]
    assert "drive_linear" not in model.velocities()
    model.hotkey_down("W", "drive_linear", 1)
    assert remote.twist(-0.2, 0.0) == {"drive_turn": 0.0}
    assert model.channel("drive_linear").source is Source.HOTKEY
    model.hotkey_up("W")
    model.hotkey_up("Y")
    # Focus lost: its row says it goes on; Space stops it.
    remote.twist(0.2, 0.0)
    model.halt("console lost focus", lock="focus lost")
    assert model.velocities() == {"drive_linear": 0.2}
    model.emergency_stop()
    assert model.velocities() == {}
    assert model.channel("drive_linear").velocity == 0.0
    # A source without a row is refused when it registers.
    with pytest.raises(MuxError, match="no row for the source 'remote'"):
        RemoteTeleop(ConsoleModel(profile))
    # A source without a registered stop still stops for a lock: its channels are zeroed.
    model = ConsoleModel(profile, clock=clock, mux=InputMux.from_text(SHIPPED + REMOTE_ROW, "m"))
    model.set_source_velocities(Source("remote"), {"drive_linear": 0.2})
    model.halt("window hidden")
    assert model.velocities() == {}
    with pytest.raises(ValueError, match="no manual source"):
        model.set_source_velocities(Source.SLIDER, {"waist": 0.1})


def test_the_robots_own_stop_is_a_lock_every_source_obeys(profile: RobotProfile) -> None:
    """A RobotModeReport that refuses motion (a UR's protective stop) halts every source
    through the mux's "robot stop" column, and nothing resumes when it clears."""
    from ocu.core.feed import feed
    from ocu.records import RobotModeReport

    model = ConsoleModel(profile)
    model.set_target("shoulder", 0.5)  # an automatic source
    model.hotkey_down("Q", "waist", 1)  # the operator's hands
    model.set_external_velocities({"neck": 0.1})  # a planner (ROS), after them
    assert set(model.velocities()) >= {"neck", "waist"}
    feed(model, RobotModeReport("RUNNING", "PROTECTIVE_STOP", False, ("protective stop",)))
    assert model.velocities() == {}
    assert not model.targets
    assert not model.held_keys
    assert model.robot.robot_mode is not None
    assert not model.robot.robot_mode.may_move
    feed(model, RobotModeReport("RUNNING", "NORMAL", True))
    model.update()
    assert model.velocities() == {}  # nothing resumed


def test_a_goal_sent_once_the_robot_is_ready_again_survives_the_ready_news(
    profile: RobotProfile,
) -> None:
    """The UR link reports the controller taking motion again (RobotModeReport, which ROS
    shows on /diagnostics at once), then says so in a SafetyEvent that stopped nothing. A
    goal that came between the two used to be cancelled by a halt for that news: seen as
    `test_ur_controller_with_robot_moves_and_stops_with_stopj` failing under load."""
    from ocu.core.feed import feed
    from ocu.records import RobotModeReport, SafetyEvent

    model = ConsoleModel(profile)
    messages: list[str] = []
    model.events.message.connect(messages.append)
    feed(model, RobotModeReport("RUNNING", "ROBOT_EMERGENCY_STOP", False, ("emergency stop",)))
    feed(model, SafetyEvent("UR controller: emergency stop: motion stopped"))
    feed(model, RobotModeReport("RUNNING", "NORMAL", True))
    model.set_target("shoulder", 0.5)  # the goal, sent on seeing NORMAL
    feed(model, SafetyEvent("UR controller: robot RUNNING: ready, nothing resumed", stopped=False))
    model.update()
    assert "shoulder" in model.targets  # still the position controller's to reach
    assert any("ready, nothing resumed" in m for m in messages)
    # A SafetyEvent that did stop something still halts everything.
    feed(model, SafetyEvent("link lost: motion commands zeroed"))
    assert not model.targets
    assert model.velocities() == {}
