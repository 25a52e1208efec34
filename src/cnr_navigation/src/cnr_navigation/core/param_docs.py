"""The README's parameter tables, printed from :mod:`cnr_navigation.core.param_tables` (ROS-free).

    /usr/bin/python3 -m cnr_navigation.core.param_docs CONFIG_DIR     # markdown on stdout

The values are those of ``CONFIG_DIR/navigation/*.yaml`` as move_base.launch loads them; there are no
defaults in code.
"""
from __future__ import annotations

from typing import Any, Dict, List, Sequence, Tuple

from cnr_navigation.core.param_files import lookup, navigation_tree, search
from cnr_navigation.core.param_tables import (
    CLEAR_RECOVERY_DIRECT, COSTMAP_CFG, COSTMAP_DIRECT, DWA_CFG, DWA_DIRECT, GENERIC_PLUGIN_CFG, INFLATION_PLUGIN_CFG,
    MOVE_BASE_CFG, MOVE_BASE_DIRECT, NAVFN_DIRECT, OBSTACLE_DIRECT, OBSTACLE_PLUGIN_CFG, ROTATE_BLP,
    ROTATE_BLP_TOLERANCE, ROTATE_RECOVERY_DIRECT, SOURCE_DIRECT, SOURCE_SEARCHED, STATIC_DIRECT)

NODE = '/move_base'
COSTMAPS: List[Tuple[str, str]] = [('global', 'global_costmap'), ('local', 'local_costmap')]


def LAYER(sub: str) -> List[Tuple[str, str]]:  # noqa: N802 (reads as a constant in GROUPS)
    return [(label, f'{ns}/{sub}') for label, ns in COSTMAPS]


#: the namespaces of the obstacle layer's observation sources, expanded from the configured
#: ``observation_sources`` of each costmap (labelled with the source's name)
SOURCES = [('<source>', f'{ns}/obstacle_layer/<source>') for _, ns in COSTMAPS]


#: (table title, declarations, [(label, namespace under the node)], searched upwards)
GROUPS = [
    ('~ (move_base, reconfigurable)', MOVE_BASE_CFG, [('', '')], False),
    ('~ (move_base, read once)', MOVE_BASE_DIRECT, [('', '')], False),
    ('~<costmap>/ (global_costmap, local_costmap; reconfigurable)', COSTMAP_CFG, COSTMAPS, False),
    ('~<costmap>/ (read once)', COSTMAP_DIRECT, COSTMAPS, False),
    ('~<costmap>/static_layer/ (reconfigurable)', GENERIC_PLUGIN_CFG, [('', 'global_costmap/static_layer')], False),
    ('~<costmap>/static_layer/ (read once)', STATIC_DIRECT, [('', 'global_costmap/static_layer')], False),
    ('~<costmap>/obstacle_layer/ (reconfigurable)', OBSTACLE_PLUGIN_CFG, LAYER('obstacle_layer'), False),
    ('~<costmap>/obstacle_layer/ (read once)', OBSTACLE_DIRECT, LAYER('obstacle_layer'), False),
    ('~<costmap>/obstacle_layer/<source>/', SOURCE_DIRECT, SOURCES, False),
    ('~<costmap>/obstacle_layer/<source>/ (searched upwards)', SOURCE_SEARCHED, SOURCES, True),
    ('~<costmap>/inflation_layer/ (reconfigurable)', INFLATION_PLUGIN_CFG, LAYER('inflation_layer'), False),
    ('~NavfnROS/', NAVFN_DIRECT, [('', 'NavfnROS')], False),
    ('~DWAPlannerROS/ (reconfigurable)', DWA_CFG, [('', 'DWAPlannerROS')], False),
    ('~DWAPlannerROS/ (read once)', DWA_DIRECT, [('', 'DWAPlannerROS')], False),
    ('~<recovery>/ (ClearCostmapRecovery)', CLEAR_RECOVERY_DIRECT,
     [('conservative_reset', 'conservative_reset'), ('aggressive_reset', 'aggressive_reset')], False),
    ('~<recovery>/ (RotateRecovery)', ROTATE_RECOVERY_DIRECT, [('', 'rotate_recovery')], False),
    ('~TrajectoryPlannerROS/ (read by RotateRecovery)', [p for p, _ in ROTATE_BLP] + [ROTATE_BLP_TOLERANCE],
     [('', 'TrajectoryPlannerROS')], False),
]


def _expand(tree: Dict[str, Any], params: Sequence[Tuple[str, str]]) -> List[Tuple[str, str]]:
    """``params`` with each ``<source>`` namespace replaced by the costmap's configured sources."""
    out = []
    for label, ns in params:
        if '<source>' not in ns:
            out.append((label, ns))
            continue
        layer = ns.split('/<source>')[0]
        names = lookup(tree, f'{NODE}/{layer}/observation_sources')
        out += [(src, ns.replace('<source>', src)) for src in (names.split() if isinstance(names, str) else [])]
    return out


def _value(tree: Dict[str, Any], params: Sequence[Tuple[str, str]], name: str, searched: bool) -> str:
    found: List[Tuple[str, Any]] = []
    for label, ns in _expand(tree, params):
        full = '/'.join(p for p in (NODE, ns) if p)
        v = lookup(tree, search(tree, full, name) or '') if searched else lookup(tree, f'{full}/{name}')
        if v is not None and (label, repr(v)) not in [(lb, repr(x)) for lb, x in found]:
            found.append((label, v))
    if not found:
        return '(set at run time)'
    if len({repr(v) for _, v in found}) == 1:
        return f'`{found[0][1]!r}`'
    return ', '.join(f'{label}: `{v!r}`' for label, v in found)


def markdown_tables(config_dir: str) -> str:
    """The README's parameter tables: declarations from param_tables, values from ``config_dir``/navigation."""
    tree = navigation_tree(config_dir, NODE)
    out = []
    for title, params, namespaces, searched in GROUPS:
        out += [f'#### `{title}`', '', '| parameter | type | range | config value | description |',
                '|---|---|---|---|---|']
        for p in params:
            rng = '' if p.minimum is None and p.maximum is None else f'{p.minimum}..{p.maximum}'
            out.append(f'| `{p.name}` | {p.kind} | {rng} | {_value(tree, namespaces, p.name, searched)} | '
                       f'{p.description} |')
        out.append('')
    return '\n'.join(out)


if __name__ == '__main__':
    import sys
    print(markdown_tables(sys.argv[1] if len(sys.argv) > 1 else 'config'))
