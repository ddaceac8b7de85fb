"""The console fixtures for every test in this folder."""

from tests.windows.console_fixtures import console, make_console, settings, sim

__all__ = ["console", "make_console", "settings", "sim"]
