"""Reading a handed-over migration state (ROS-free): every problem is one ValueError that names the field.

The state comes from another instance of mfg as JSON (``migration_manager.core.state``). :func:`state_section`
wraps one of its objects in a :class:`cnr_params.Section`, whose errors read
``mfg state: <field>.<key>: <problem>`` (:class:`cnr_params.ConfigError` is a ValueError), and the helpers below
read what a Section cannot: cell indices, lists of them, table rows, numbers that may be NaN.
"""
from __future__ import annotations

import math
from typing import Any, List, Optional

from cnr_params import ConfigError, Section

SOURCE = 'mfg state'


def state_section(data: Any, field: str) -> Section:
    """``data`` (an object of the state at ``field``) as a Section; ValueError if it is not an object."""
    if not isinstance(data, dict):
        raise ConfigError(SOURCE, field, f'expected an object, got {type(data).__name__}')
    return Section(data, SOURCE, field)


def check_cell(sec: Section, key: str, value: Any, cells: Optional[int]) -> int:
    """A cell index (``0 <= value < cells`` when the number of cells is known)."""
    if isinstance(value, bool) or not isinstance(value, int):
        raise sec.error(key, f'expected a cell index, got {value!r}')
    if value < 0 or (cells is not None and value >= cells):
        raise sec.error(key, f'cell {value} is outside the grid'
                             f'{f" (0..{cells - 1})" if cells is not None else ""}')
    return value


def cell(sec: Section, key: str, cells: Optional[int], optional: bool = False) -> Optional[int]:
    """The cell index at ``key`` (``None`` allowed if ``optional``)."""
    value = sec.raw(key)
    if value is None and optional:
        return None
    return check_cell(sec, key, value, cells)


def cell_list(sec: Section, key: str, cells: Optional[int]) -> List[int]:
    value = sec.raw(key)
    if not isinstance(value, list):
        raise sec.error(key, f'expected a list of cell indices, got {type(value).__name__}')
    return [check_cell(sec, key, v, cells) for v in value]


def rows(sec: Section, key: str, width: int) -> List[list]:
    """A list of lists of ``width`` items each (a table)."""
    value = sec.raw(key)
    if not isinstance(value, list):
        raise sec.error(key, f'expected a list, got {type(value).__name__}')
    for i, row in enumerate(value):
        if not isinstance(row, list) or len(row) != width:
            raise sec.error(key, f'item {i}: expected a list of {width} values, got {row!r}')
    return value


def number(sec: Section, key: str, value: Any, allow_nan: bool = False) -> float:
    """A finite number (or NaN if ``allow_nan``) found in ``key``."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise sec.error(key, f'expected a number, got {value!r}')
    value = float(value)
    if math.isinf(value) or (math.isnan(value) and not allow_nan):
        raise sec.error(key, f'must be finite, got {value}')
    return value
