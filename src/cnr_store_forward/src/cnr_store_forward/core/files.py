"""Small files written whole: atomically (temporary file + rename), durably on request (fsync)."""
from __future__ import annotations

import json
import os
from typing import Any, Dict, Optional


def fsync_directory(directory: str) -> None:
    """Make the entries of ``directory`` (created, renamed, removed files) durable."""
    fd = os.open(directory, os.O_RDONLY | os.O_DIRECTORY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def write_atomic(path: str, data: bytes, durable: bool) -> None:
    """Replace ``path`` by ``data``: readers (and a restart after a crash) see the old or the new content,
    never a mix. With ``durable`` the new content also survives a power loss once this returns."""
    tmp = f'{path}.tmp'
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
    try:
        view = memoryview(data)
        while view:
            view = view[os.write(fd, view):]
        if durable:
            os.fsync(fd)
    finally:
        os.close(fd)
    os.replace(tmp, path)
    if durable:
        fsync_directory(os.path.dirname(os.path.abspath(path)))


def write_json(path: str, value: Dict[str, Any], durable: bool) -> None:
    write_atomic(path, (json.dumps(value, sort_keys=True) + '\n').encode(), durable)


def read_json(path: str) -> Optional[Dict[str, Any]]:
    """The JSON object in ``path``; None if the file is missing, unreadable or not a JSON object."""
    try:
        with open(path, 'rb') as stream:
            value = json.loads(stream.read().decode())
    except (OSError, ValueError):
        return None
    return value if isinstance(value, dict) else None
