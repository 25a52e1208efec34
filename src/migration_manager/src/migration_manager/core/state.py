"""The state a module hands over in a migration: a JSON object, zlib-compressed on the wire.

Each movable node documents the keys of its state in its README ("Migration state"). Floats that are not
finite (NaN, inf) are kept (Python's JSON writes them as NaN/Infinity and reads them back).
"""
from __future__ import annotations

import json
import zlib
from typing import Any, Dict


class StateError(ValueError):
    """A state that cannot be decoded or does not belong to the module."""


#: zlib level: 1, not the default 6. The active instance encodes its state every replicate_period; for a
#: store of 3000 measurements (387 KB of JSON) level 6 took 20 ms and level 1 3.5 ms of this machine's CPU for
#: 7 % more bytes (181 vs 194 KB; JSON itself 7.8 ms): at 2 Hz, level 6's compression alone was 0.04 CPU, 12 %
#: of the robot's third of a CPU.
COMPRESSION = 1


def encode(module: str, state: Dict[str, Any]) -> bytes:
    return zlib.compress(json.dumps({'module': module, 'state': state}, separators=(',', ':')).encode(),
                         COMPRESSION)


def decode(module: str, data: bytes) -> Dict[str, Any]:
    try:
        doc = json.loads(zlib.decompress(bytes(data)).decode())
    except (zlib.error, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise StateError(f'state of {module}: not a compressed JSON state ({exc})') from None
    if not isinstance(doc, dict) or doc.get('module') != module or not isinstance(doc.get('state'), dict):
        raise StateError(f'state of {module}: made by {doc.get("module") if isinstance(doc, dict) else "?"!r}')
    return doc['state']
