"""Parser of the Kestrel serial line format (ROS-free).

One measurement per line, ASCII, terminated by CR and/or LF. Accepted forms:

* ``23.4``                       temperature in degC
* ``T,23.4`` / ``TEMP,23.4,C``    a tag, the value and an optional unit (C or F)
* ``$KES,23.4,C*hh``             NMEA-like with an optional XOR checksum of the text between $ and *

Anything else is garbage: :func:`parse_line` raises :class:`ParseError` with the reason.
"""
from __future__ import annotations

import math
from functools import reduce


class ParseError(ValueError):
    pass


def _checksum_ok(body: str, given: str) -> bool:
    try:
        return reduce(lambda a, c: a ^ ord(c), body, 0) == int(given, 16)
    except ValueError:
        return False


def parse_line(line: str) -> float:
    """Temperature in degC from one line."""
    text = line.strip()
    if not text:
        raise ParseError('empty line')
    if text.startswith('$'):
        body, _, check = text[1:].partition('*')
        if check and not _checksum_ok(body, check):
            raise ParseError(f'bad checksum in {text!r}')
        fields = body.split(',')[1:]
    else:
        fields = text.split(',')
        if len(fields) > 1 and not _is_number(fields[0]):
            fields = fields[1:]
    if not fields or not _is_number(fields[0]):
        raise ParseError(f'no temperature in {text!r}')
    value = float(fields[0])
    unit = fields[1].strip().upper() if len(fields) > 1 else 'C'
    if unit == 'F':
        value = (value - 32.0) * 5.0 / 9.0
    elif unit != 'C':
        raise ParseError(f'unknown unit {unit!r} in {text!r}')
    if not math.isfinite(value) or not -60.0 <= value <= 150.0:
        raise ParseError(f'temperature {value} out of the sensor range')
    return value


def _is_number(s: str) -> bool:
    try:
        float(s)
        return True
    except ValueError:
        return False
