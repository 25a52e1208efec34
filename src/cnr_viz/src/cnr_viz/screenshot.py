"""A window of an X display as a PNG (python3-xlib and Pillow; no ROS).

``grab(display, title_part, path)`` finds the top-level window whose name contains ``title_part`` (rviz names
its window after the config file: ``mission.rviz - RViz``) and writes what it shows; with no such window, the
whole screen. ``render_panel`` finds where rviz draws the 3-D view in that window (OGRE's own X window: the
deepest child covering a large part of it), for checking where a map point landed.
"""
from __future__ import annotations

from typing import Optional, Tuple


def _find(win, title_part: str):
    try:
        name = win.get_wm_name()
    except Exception:        # a window that went away meanwhile (Xlib raises its own error classes)
        name = None
    if isinstance(name, bytes):
        name = name.decode(errors='replace')
    if name and title_part in name:
        return win
    try:
        children = win.query_tree().children
    except Exception:
        return None
    for child in children:
        hit = _find(child, title_part)
        if hit is not None:
            return hit
    return None


def grab(display: str, title_part: str, path: str) -> Tuple[int, int, bool]:
    """Write the window (or, without one, the screen) to ``path``; (width, height, window found)."""
    from PIL import Image
    from Xlib import X, display as xdisplay

    d = xdisplay.Display(display)
    try:
        root = d.screen().root
        win = _find(root, title_part) if title_part else None
        target = win if win is not None else root
        geo = target.get_geometry()
        raw = target.get_image(0, 0, geo.width, geo.height, X.ZPixmap, 0xFFFFFFFF)
        img = Image.frombytes('RGB', (geo.width, geo.height), raw.data, 'raw', 'BGRX')
        img.save(path)
        return geo.width, geo.height, win is not None
    finally:
        d.close()


def window_present(display: str, title_part: str) -> Optional[bool]:
    """Whether a window named with ``title_part`` is mapped on ``display`` (None: the display cannot be opened)."""
    from Xlib import display as xdisplay
    from Xlib.error import DisplayError
    try:
        d = xdisplay.Display(display)
    except DisplayError:
        return None
    try:
        return _find(d.screen().root, title_part) is not None
    finally:
        d.close()


def render_panel(display: str, title_part: str) -> Optional[Tuple[int, int, int, int]]:
    """(x, y, width, height) in the window named with ``title_part`` of its deepest child window covering at
    least a quarter of it (rviz's render panel), or None."""
    from Xlib import display as xdisplay

    d = xdisplay.Display(display)
    try:
        top = _find(d.screen().root, title_part)
        if top is None:
            return None
        tg = top.get_geometry()
        best = None       # (depth, x, y, w, h)

        def walk(win, depth: int, ox: int, oy: int) -> None:
            nonlocal best
            for child in win.query_tree().children:
                g = child.get_geometry()
                x, y = ox + g.x, oy + g.y
                if g.width * g.height >= tg.width * tg.height / 4 and (best is None or depth > best[0]):
                    best = (depth, x, y, g.width, g.height)
                walk(child, depth + 1, x, y)
        walk(top, 1, 0, 0)
        return None if best is None else best[1:]
    finally:
        d.close()
