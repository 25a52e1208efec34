"""move_base's parameter tree as move_base.launch loads it from config/navigation (ROS-free).

Used where the tree is needed without roslaunch: the start-up audit (which sets it on a private master),
the README tables (which show the configured values), and tools and tests that build the navigation cores
as the node would (:func:`read_config`).
"""
from __future__ import annotations

import os
from typing import TYPE_CHECKING, Any, Dict, List, Optional, Tuple

from cnr_params import load_yaml

if TYPE_CHECKING:
    from cnr_navigation.core.param_reader import NavigationParams

#: (file in config/navigation, namespace under the node it is loaded into), in move_base.launch's order
NAV_FILES: List[Tuple[str, str]] = [
    ('costmap_common.yaml', 'global_costmap'), ('costmap_common.yaml', 'local_costmap'), ('local_costmap.yaml', ''),
    ('global_costmap.yaml', ''), ('dwa_local_planner.yaml', ''), ('global_planner.yaml', ''), ('move_base.yaml', '')]


def navigation_tree(config_dir: str, node: str = '/move_base') -> Dict[str, Any]:
    """Every parameter under ``node`` by its absolute name, as roslaunch sets them from the files (dictionaries
    flattened into their leaves, so later files add to a namespace rather than replace it)."""
    out: Dict[str, Any] = {}

    def add(name: str, value: Any) -> None:
        if isinstance(value, dict):
            for key, sub in value.items():
                add(f'{name}/{key}', sub)
        else:
            out[name] = value
    for file_name, ns in NAV_FILES:
        for key, value in load_yaml(os.path.join(config_dir, 'navigation', file_name)).items():
            add('/'.join(p for p in (node, ns, key) if p), value)
    return out


def lookup(tree: Dict[str, Any], name: str) -> Optional[Any]:
    """The value of the parameter ``name`` in a flat ``tree``, or None."""
    return tree.get(name)


def search(tree: Dict[str, Any], namespace: str, key: str) -> Optional[str]:
    """searchParam: the name of ``key`` in ``namespace`` or the nearest namespace above it, or None."""
    parts = namespace.rstrip('/').split('/')
    while parts:
        name = '/'.join(parts + [key])
        if name in tree:
            return name
        parts.pop()
    return None


class TreeReader:
    """:class:`cnr_navigation.core.param_reader.ParamReader` over a flat tree (no master)."""

    def __init__(self, tree: Dict[str, Any]) -> None:
        self.tree = dict(tree)

    def get(self, name: str) -> Any:
        from cnr_navigation.core.param_reader import missing
        if name not in self.tree:
            raise missing(name)
        return self.tree[name]

    def get_optional(self, name: str) -> Optional[Any]:
        return self.tree.get(name)

    def has(self, name: str) -> bool:
        return name in self.tree

    def search(self, namespace: str, key: str) -> Optional[str]:
        return search(self.tree, namespace, key)

    def set(self, name: str, value: Any) -> None:
        self.tree[name] = value


def read_config(config_dir: str, node: str = '/move_base') -> 'NavigationParams':
    """Everything the move_base node would read from ``config_dir``/navigation (validated)."""
    from cnr_navigation.core.param_reader import read_navigation_params
    return read_navigation_params(TreeReader(navigation_tree(config_dir, node)), node)
