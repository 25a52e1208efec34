"""The README's parameter tables, printed from :mod:`cnr_navigation.core.param_tables` (ROS-free).

    /usr/bin/python3 -m cnr_navigation.core.param_docs      # markdown on stdout
"""
from __future__ import annotations

from cnr_navigation.core.param_tables import (
    CLEAR_RECOVERY_DIRECT, COSTMAP_CFG, COSTMAP_DIRECT, DWA_CFG, DWA_DIRECT, GENERIC_PLUGIN_CFG, INFLATION_PLUGIN_CFG,
    MOVE_BASE_CFG, MOVE_BASE_DIRECT, NAVFN_DIRECT, OBSTACLE_DIRECT, OBSTACLE_PLUGIN_CFG, ROTATE_RECOVERY_DIRECT,
    SOURCE_DIRECT, SOURCE_SEARCHED, STATIC_DIRECT)


def markdown_tables() -> str:
    """The README's parameter tables, generated from the declarations above (one source of truth)."""
    groups = [
        ('~ (move_base, reconfigurable)', MOVE_BASE_CFG), ('~ (move_base, read once)', MOVE_BASE_DIRECT),
        ('~<costmap>/ (global_costmap, local_costmap; reconfigurable)', COSTMAP_CFG),
        ('~<costmap>/ (read once)', COSTMAP_DIRECT),
        ('~<costmap>/static_layer/ (reconfigurable)', GENERIC_PLUGIN_CFG),
        ('~<costmap>/static_layer/ (read once)', STATIC_DIRECT),
        ('~<costmap>/obstacle_layer/ (reconfigurable)', OBSTACLE_PLUGIN_CFG),
        ('~<costmap>/obstacle_layer/ (read once)', OBSTACLE_DIRECT),
        ('~<costmap>/obstacle_layer/<source>/', SOURCE_DIRECT + SOURCE_SEARCHED),
        ('~<costmap>/inflation_layer/ (reconfigurable)', INFLATION_PLUGIN_CFG),
        ('~NavfnROS/', NAVFN_DIRECT), ('~DWAPlannerROS/ (reconfigurable)', DWA_CFG),
        ('~DWAPlannerROS/ (read once)', DWA_DIRECT),
        ('~<recovery>/ (ClearCostmapRecovery)', CLEAR_RECOVERY_DIRECT),
        ('~<recovery>/ (RotateRecovery)', ROTATE_RECOVERY_DIRECT),
    ]
    out = []
    for title, params in groups:
        out += [f'#### `{title}`', '', '| parameter | type | default | range | description |', '|---|---|---|---|---|']
        for p in params:
            rng = '' if p.minimum is None and p.maximum is None else f'{p.minimum}..{p.maximum}'
            out.append(f'| `{p.name}` | {p.kind} | `{p.default!r}` | {rng} | {p.description} |')
        out.append('')
    return '\n'.join(out)


if __name__ == '__main__':
    print(markdown_tables())
