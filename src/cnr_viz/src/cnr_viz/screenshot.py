"""A window of an X display as a PNG (python3-xlib and Pillow; no ROS).

``grab(display, title_part, path)`` finds the viewable window whose name contains ``title_part`` (rviz names its
main window after the config file: ``mission.rviz - RViz``, ``mission.rviz* - RViz`` once changed) and writes
what it shows; with no such window, the whole screen. ``render_panel`` finds where rviz draws the 3-D view in
that window (OGRE's own X window: the deepest child covering a large part of it), for checking where a map point
landed.
"""
from __future__ import annotations

from typing import Optional, Tuple


def _find(win, title_part: str):
    """The first viewable window under ``win`` whose name contains ``title_part``, or None."""
    from Xlib import X
    try:
        name = win.get_wm_name()
        viewable = win.get_attributes().map_state == X.IsViewable
    except Exception:        # a window that went away meanwhile (Xlib raises its own error classes)
        name, viewable = None, False
    if isinstance(name, bytes):
        name = name.decode(errors='replace')
    if name and title_part in name and viewable:
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
        screen = d.screen()
        root = screen.root
        win = _find(root, title_part) if title_part else None
        x, y, w, h = 0, 0, screen.width_in_pixels, screen.height_in_pixels
        if win is not None:          # the window's rectangle of the screen (what is visible of it)
            geo = win.get_geometry()
            pos = root.translate_coords(win, 0, 0)
            x0, y0 = max(pos.x, 0), max(pos.y, 0)
            w, h = min(pos.x + geo.width, w) - x0, min(pos.y + geo.height, h) - y0
            x, y = x0, y0
        raw = root.get_image(x, y, w, h, X.ZPixmap, 0xFFFFFFFF)
        img = Image.frombytes('RGB', (w, h), raw.data, 'raw', 'BGRX')
        img.save(path)
        return w, h, win is not None
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
