"""A strict reader of parsed TOML tables: unknown or missing keys, wrong types, non-finite numbers and subnormal
ones (nonzero, below 2.2e-308) are refused with one `BadInput` naming the source file and the field's path
(`agents[3].start_m[1]`)."""

from __future__ import annotations

import difflib
import math
import sys
from collections.abc import Callable
from typing import Any

from reconswarm.errors import BadInput
from reconswarm.scenario import limits


class TableReader:
    """Walks the parsed TOML, collecting the first error with its field path."""

    def __init__(self, source: str) -> None:
        self.source = source

    def fail(self, path: str, msg: str) -> BadInput:
        return BadInput(f"{self.source}: {path}: {msg}")

    def table(self, data: Any, path: str) -> dict[str, Any]:
        if not isinstance(data, dict):
            raise self.fail(path, f"expected a table, got {kind_of(data)}")
        return data

    def keys(self, data: dict[str, Any], path: str, required: set[str], optional: set[str]) -> None:
        for key in data:
            if key not in required | optional:
                near = difflib.get_close_matches(str(key), sorted(required | optional), n=1, cutoff=0.6)
                raise self.fail(join_path(path, key), "unknown key" + (f" (did you mean {near[0]}?)" if near else ""))
        for key in sorted(required):
            if key not in data:
                raise self.fail(join_path(path, key), "missing key")

    def _default(self, where: str, default: Any) -> Any:
        """A key that is absent: its default, or the one-line "missing key" error when it has none."""
        if default is None:
            raise self.fail(where, "missing key")
        return default

    def number(self, data: dict[str, Any], path: str, key: str, default: float | None = None,
               check: Callable[[float], bool] | None = None, need: str = "") -> float:
        where = join_path(path, key)
        if key not in data:
            return self._default(where, default)
        v = data[key]
        if isinstance(v, bool) or not isinstance(v, int | float):
            raise self.fail(where, f"expected a number, got {kind_of(v)}")
        if not math.isfinite(v):
            raise self.fail(where, f"must be finite, got {v}")
        subnormal(float(v), where, self.fail)
        if check is not None and not check(float(v)):
            raise self.fail(where, f"must be {need}, got {v}")
        return float(v)

    def integer(self, data: dict[str, Any], path: str, key: str, default: int | None = None,
                lo: int | None = None) -> int:
        where = join_path(path, key)
        if key not in data:
            return self._default(where, default)
        v = data[key]
        if isinstance(v, bool) or not isinstance(v, int):
            raise self.fail(where, f"expected an integer, got {kind_of(v)}")
        if lo is not None and v < lo:
            raise self.fail(where, f"must be >= {lo}, got {v}")
        return int(v)

    def string(self, data: dict[str, Any], path: str, key: str, default: str | None = None) -> str:
        where = join_path(path, key)
        if key not in data:
            return self._default(where, default)
        v = data[key]
        if not isinstance(v, str) or not v:
            raise self.fail(where, f"expected a non-empty string, got {kind_of(v)}")
        return v

    def point(self, v: Any, where: str) -> tuple[float, float]:
        if not isinstance(v, list) or len(v) != 2:
            raise self.fail(where, f"expected [x, y], got {kind_of(v)}")
        out = []
        for k, c in enumerate(v):
            if isinstance(c, bool) or not isinstance(c, int | float):
                raise self.fail(f"{where}[{k}]", f"expected a number, got {kind_of(c)}")
            if not math.isfinite(c):
                raise self.fail(f"{where}[{k}]", f"must be finite, got {c}")
            subnormal(float(c), f"{where}[{k}]", self.fail)
            limits.check_point(where, k, c, self.fail)
            out.append(float(c))
        return (out[0], out[1])

    def point_key(self, data: dict[str, Any], path: str, key: str,
                  default: tuple[float, float] | None = None) -> tuple[float, float]:
        if key not in data:
            return self._default(join_path(path, key), default)
        return self.point(data[key], join_path(path, key))


def subnormal(v: float, where: str, fail: Callable[[str, str], Exception]) -> None:
    """0 or a normal float: a nonzero value below the smallest normal (2.2e-308) loses its precision, and a division
    by it, or by its square root, is not finite (a head offset of 5e-324 m made a robot NaN from the first step)."""
    if v != 0.0 and abs(v) < sys.float_info.min:
        raise fail(where, f"must be 0 or a normal float (magnitude at least {sys.float_info.min:.6g}), got {v!r}")


def join_path(path: str, key: str) -> str:
    return f"{path}.{key}" if path else key


def kind_of(v: Any) -> str:
    if isinstance(v, bool):
        return f"boolean {str(v).lower()}"
    if isinstance(v, str):
        return f"string {v!r}"
    if isinstance(v, list):
        return "array"
    if isinstance(v, dict):
        return "table"
    return f"{type(v).__name__} {v!r}"
