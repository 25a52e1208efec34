"""Small files written whole: atomically (a temporary file beside the target, then a rename), durably on request.

No ROS imports: the one atomic write of the workspace, for nodes, tools, tests and benchmarks alike.
"""
from __future__ import annotations

import contextlib
import json
import os
import stat
import tempfile
from typing import Any, Dict, Optional, Union


def fsync_directory(directory: str) -> None:
    """Make the entries of ``directory`` (created, renamed, removed files) durable."""
    fd = os.open(directory, os.O_RDONLY | os.O_DIRECTORY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def write_atomic(path: str, data: Union[bytes, str], durable: bool = False) -> None:
    """Replace ``path`` by ``data`` (``str`` is written as UTF-8): readers, and a restart after a crash, see the old
    or the new content, never a mix. The temporary file is unique (concurrent writers do not collide) and removed
    if the write fails; the file keeps the permissions of the one it replaces (a new one: 0666 less the umask).
    With ``durable`` the new content also survives a power loss once this returns (file and directory fsync'ed)."""
    raw = data.encode('utf-8') if isinstance(data, str) else data
    directory = os.path.dirname(os.path.abspath(path))
    fd, tmp = tempfile.mkstemp(prefix=f'.{os.path.basename(path)}.', suffix='.tmp', dir=directory)
    try:
        try:
            mode = stat.S_IMODE(os.stat(path).st_mode)
        except OSError:
            mode = 0o666 & ~_umask()
        os.fchmod(fd, mode)
        view = memoryview(raw)
        while view:
            view = view[os.write(fd, view):]
        if durable:
            os.fsync(fd)
        os.close(fd)
        fd = -1
        os.replace(tmp, path)
    except BaseException:
        if fd >= 0:
            os.close(fd)
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise
    if durable:
        fsync_directory(directory)


def write_json(path: str, value: Any, durable: bool = False, indent: Optional[int] = None,
               sort_keys: bool = True) -> None:
    """``value`` as JSON (one trailing newline), written with :func:`write_atomic`."""
    write_atomic(path, json.dumps(value, sort_keys=sort_keys, indent=indent) + '\n', durable)


def read_json(path: str) -> Optional[Dict[str, Any]]:
    """The JSON object in ``path``; None if the file is missing, unreadable or not a JSON object."""
    try:
        with open(path, 'rb') as stream:
            value = json.loads(stream.read().decode())
    except (OSError, ValueError):
        return None
    return value if isinstance(value, dict) else None
