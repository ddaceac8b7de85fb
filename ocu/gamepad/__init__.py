"""The game controller: SDL's pads read on a thread of their own, mapped onto the console model.

`pad` names what a pad has (SDL's axis and button names) and what a poll reads; `mapping`
loads the TOML mapping file; `calibration` holds each pad's axis ranges and centres;
`shaping` turns a raw axis into a command (calibration, deadzone, expo); `teleop` is the
deadman, the arming and the bindings over a ConsoleModel; `poller` reads SDL on the
"ocu-gamepad" thread; `virtual` makes an SDL virtual pad for tests and benchmarks. No Qt.
"""
