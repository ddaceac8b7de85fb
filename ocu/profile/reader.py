"""Reading one TOML table of a profile: typed values, every error naming the file and the key."""

from __future__ import annotations

import math
from collections.abc import Collection
from typing import Any

from ocu.profile.keys import ProfileError, did_you_mean


class TableReader:
    """Typed access to a TOML table with error messages that name the key.

    With `keys`, a key outside them is refused at once, before any value is read.
    """

    def __init__(
        self,
        table: dict[str, Any],
        where: str,
        keys: Collection[str] | None,
        unknown: str = "unknown key",
    ) -> None:
        self.table = table
        self.where = where
        if keys is not None:
            errors = [
                f"{where}.{key}: {unknown}; {did_you_mean(key, keys)}"
                for key in table
                if key not in keys
            ]
            if errors:
                raise ProfileError("; ".join(errors))

    def _get(self, key: str) -> Any:
        if key not in self.table:
            raise ProfileError(f"{self.where}.{key}: missing")
        return self.table[key]

    def sub(
        self, key: str, keys: Collection[str] | None, unknown: str = "unknown key"
    ) -> TableReader:
        value = self._get(key)
        if not isinstance(value, dict):
            raise ProfileError(f"{self.where}.{key}: must be a table")
        return TableReader(value, f"{self.where}.{key}", keys, unknown)

    def number(self, key: str, *, low: float | None = None, high: float | None = None) -> float:
        value = self._get(key)
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ProfileError(f"{self.where}.{key}: must be a number, got {value!r}")
        number = float(value)
        if not math.isfinite(number):
            raise ProfileError(f"{self.where}.{key}: must be finite, got {value!r}")
        if low is not None and number < low:
            raise ProfileError(f"{self.where}.{key}: must be >= {low}, got {value!r}")
        if high is not None and number > high:
            raise ProfileError(f"{self.where}.{key}: must be <= {high}, got {value!r}")
        return number

    def integer(self, key: str, *, low: int, high: int) -> int:
        value = self._get(key)
        if isinstance(value, bool) or not isinstance(value, int):
            raise ProfileError(f"{self.where}.{key}: must be an integer, got {value!r}")
        if not low <= value <= high:
            raise ProfileError(f"{self.where}.{key}: must be in [{low}, {high}], got {value}")
        return value

    def string(self, key: str) -> str:
        value = self._get(key)
        if not isinstance(value, str) or not value:
            raise ProfileError(f"{self.where}.{key}: must be a non-empty string")
        return value

    def optional(self, key: str) -> bool:
        return key in self.table

    def boolean(self, key: str) -> bool:
        value = self._get(key)
        if not isinstance(value, bool):
            raise ProfileError(f"{self.where}.{key}: must be true or false, got {value!r}")
        return value

    def choice(self, key: str, choices: tuple[str, ...]) -> str:
        value = self.string(key)
        if value not in choices:
            raise ProfileError(f"{self.where}.{key}: must be one of {choices}, got {value!r}")
        return value

    def numbers(
        self, key: str, lengths: tuple[int, ...], *, low: float | None = None
    ) -> tuple[float, ...]:
        value = self._get(key)
        if (
            not isinstance(value, list)
            or len(value) not in lengths
            or not all(
                isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
                for v in value
            )
        ):
            sizes = " or ".join(str(n) for n in lengths)
            raise ProfileError(f"{self.where}.{key}: must be a list of {sizes} finite numbers")
        if low is not None and any(v < low for v in value):
            raise ProfileError(f"{self.where}.{key}: every value must be >= {low}")
        return tuple(float(v) for v in value)
