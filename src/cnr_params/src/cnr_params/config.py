"""Typed access to configuration dictionaries with one-line errors.

Every value a node reads from a YAML file or the parameter server goes through a
:class:`Section`, which knows where the values came from (a file name or a
parameter namespace) and the dotted path of the field. A bad value raises
:class:`ConfigError` whose message names both, e.g.::

    config/robot.yaml: kinematics.max_linear_speed: must be > 0, got -1.0

Node ``main()`` functions are wrapped in :func:`exit_on_config_error`, which prints
that single line (no traceback) and exits with status 2.
"""
from __future__ import annotations

import functools
import math
import os
import sys
from typing import Any, Callable, Dict, Iterable, List, Optional, Sequence, TypeVar

import yaml

T = TypeVar('T')
_MISSING = object()

EXIT_CONFIG = 2


class ConfigError(ValueError):
    """A configuration value is missing or invalid.

    Args:
        source: file name or parameter namespace the value came from.
        field: dotted path of the field inside the source ('' for the whole source).
        problem: what is wrong, in a few words.
    """

    def __init__(self, source: str, field: str, problem: str) -> None:
        self.source = source
        self.field = field
        self.problem = problem
        where = f'{source}: {field}' if field else source
        super().__init__(f'{where}: {problem}')


def load_yaml(path: str) -> Dict[str, Any]:
    """Read a YAML mapping from ``path``.

    Raises:
        ConfigError: the file is missing, unreadable, not YAML or not a mapping.
    """
    try:
        with open(path, 'r', encoding='utf-8') as stream:
            data = yaml.safe_load(stream)
    except FileNotFoundError:
        raise ConfigError(path, '', 'file not found') from None
    except OSError as exc:
        raise ConfigError(path, '', f'cannot read: {exc.strerror}') from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, 'problem_mark', None)
        where = f' (line {mark.line + 1}, column {mark.column + 1})' if mark else ''
        problem = getattr(exc, 'problem', None) or 'malformed YAML'
        raise ConfigError(path, '', f'malformed YAML{where}: {problem}') from None
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise ConfigError(path, '', f'expected a mapping at the top level, got {type(data).__name__}')
    return data


class Section:
    """A mapping of configuration values that remembers where it came from.

    Args:
        data: the values.
        source: file name or parameter namespace, used in error messages.
        prefix: dotted path of this section inside the source.
    """

    def __init__(self, data: Dict[str, Any], source: str, prefix: str = '') -> None:
        if not isinstance(data, dict):
            raise ConfigError(source, prefix, f'expected a mapping, got {type(data).__name__}')
        self.data = data
        self.source = source
        self.prefix = prefix

    @classmethod
    def from_file(cls, path: str) -> 'Section':
        return cls(load_yaml(path), path)

    def path(self, key: str) -> str:
        return f'{self.prefix}.{key}' if self.prefix else key

    def error(self, key: str, problem: str) -> ConfigError:
        return ConfigError(self.source, self.path(key), problem)

    def __contains__(self, key: str) -> bool:
        return key in self.data

    def keys(self) -> Iterable[str]:
        return self.data.keys()

    def raw(self, key: str, default: Any = _MISSING) -> Any:
        if key in self.data:
            return self.data[key]
        if default is _MISSING:
            raise self.error(key, 'missing')
        return default

    def section(self, key: str, default: Any = _MISSING) -> 'Section':
        value = self.raw(key, {} if default is _MISSING else default)
        if key not in self.data and default is _MISSING:
            raise self.error(key, 'missing')
        return Section(value if value is not None else {}, self.source, self.path(key))

    def sections(self, key: str) -> List['Section']:
        """A list of mappings under ``key`` (missing means empty)."""
        value = self.raw(key, [])
        if value is None:
            return []
        if not isinstance(value, list):
            raise self.error(key, f'expected a list, got {type(value).__name__}')
        return [Section(v, self.source, f'{self.path(key)}[{i}]') for i, v in enumerate(value)]

    def number(self, key: str, default: Any = _MISSING, *, minimum: Optional[float] = None,
               maximum: Optional[float] = None, positive: bool = False, nonnegative: bool = False,
               allow_inf: bool = False) -> float:
        """A finite float with optional bounds (``positive`` means > 0)."""
        value = self.raw(key, default)
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise self.error(key, f'expected a number, got {value!r}')
        value = float(value)
        if math.isnan(value) or (math.isinf(value) and not allow_inf):
            raise self.error(key, f'must be finite, got {value}')
        if positive and not value > 0:
            raise self.error(key, f'must be > 0, got {value}')
        if nonnegative and value < 0:
            raise self.error(key, f'must be >= 0, got {value}')
        if minimum is not None and value < minimum:
            raise self.error(key, f'must be >= {minimum}, got {value}')
        if maximum is not None and value > maximum:
            raise self.error(key, f'must be <= {maximum}, got {value}')
        return value

    def integer(self, key: str, default: Any = _MISSING, *, minimum: Optional[int] = None,
                maximum: Optional[int] = None) -> int:
        value = self.raw(key, default)
        if isinstance(value, bool) or not isinstance(value, int):
            raise self.error(key, f'expected an integer, got {value!r}')
        if minimum is not None and value < minimum:
            raise self.error(key, f'must be >= {minimum}, got {value}')
        if maximum is not None and value > maximum:
            raise self.error(key, f'must be <= {maximum}, got {value}')
        return value

    def boolean(self, key: str, default: Any = _MISSING) -> bool:
        value = self.raw(key, default)
        if not isinstance(value, bool):
            raise self.error(key, f'expected true or false, got {value!r}')
        return value

    def string(self, key: str, default: Any = _MISSING, *, choices: Optional[Sequence[str]] = None) -> str:
        value = self.raw(key, default)
        if not isinstance(value, str):
            raise self.error(key, f'expected a string, got {value!r}')
        if choices is not None and value not in choices:
            raise self.error(key, f"unknown value '{value}' (expected one of: {', '.join(choices)})")
        return value

    def vector(self, key: str, length: Optional[int] = None, default: Any = _MISSING) -> List[float]:
        """A list of finite numbers, optionally of a fixed length."""
        value = self.raw(key, default)
        if not isinstance(value, (list, tuple)):
            raise self.error(key, f'expected a list of numbers, got {value!r}')
        if length is not None and len(value) != length:
            raise self.error(key, f'expected {length} numbers, got {len(value)}')
        out = []
        for item in value:
            if isinstance(item, bool) or not isinstance(item, (int, float)) or not math.isfinite(item):
                raise self.error(key, f'expected finite numbers, got {item!r}')
            out.append(float(item))
        return out

    def file_path(self, key: str, default: Any = _MISSING, *, must_exist: bool = True) -> str:
        """A path; relative paths are resolved against the directory of the source file."""
        value = self.string(key, default)
        if not os.path.isabs(value) and os.path.isfile(self.source):
            value = os.path.join(os.path.dirname(os.path.abspath(self.source)), value)
        if must_exist and not os.path.exists(value):
            raise self.error(key, f'file not found: {value}')
        return value


def exit_on_config_error(main: Callable[..., T]) -> Callable[..., T]:
    """Decorate a node's ``main()``: a :class:`ConfigError` prints one line and exits with status 2."""

    @functools.wraps(main)
    def wrapper(*args: Any, **kwargs: Any) -> T:
        try:
            return main(*args, **kwargs)
        except ConfigError as exc:
            prog = os.path.basename(sys.argv[0]) if sys.argv and sys.argv[0] else 'node'
            sys.stderr.write(f'[{prog}] configuration error: {exc}\n')
            sys.stderr.flush()
            rospy = sys.modules.get('rospy')
            if rospy is not None and rospy.core.is_initialized():
                # a node that found the error after init_node may have started threads that are not daemons
                # (tf2, actionlib, its own loops): SystemExit would leave the process waiting for them, and its
                # launch and migration agent with it. Unregister from the master, then leave at once.
                rospy.signal_shutdown('configuration error')
                sys.stdout.flush()
                os._exit(EXIT_CONFIG)
            raise SystemExit(EXIT_CONFIG) from None

    return wrapper
