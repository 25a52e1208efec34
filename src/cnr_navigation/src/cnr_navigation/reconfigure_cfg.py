"""Body of the ``cfg/*.cfg`` scripts: a dynamic_reconfigure ParameterGenerator per reconfigurable group.

Runs at build time under catkin's ``generate_dynamic_reconfigure_options``; the groups are declared in
:mod:`cnr_navigation.core.param_tables`, so names and ranges agree with what the node reads. The default
given to dynamic_reconfigure is move_base's documented one (``Param.upstream_default``); the servers start
from the values the node read from config/navigation, which are all required.
"""
from __future__ import annotations

from cnr_navigation.core.param_tables import RECONFIGURABLE


def generate_cfg(stem: str) -> int:
    """Body of ``cfg/<stem>.cfg``: declare the group :data:`RECONFIGURABLE` [stem] to dynamic_reconfigure.

    Runs at build time under catkin's dynamic_reconfigure macros (``generate_dynamic_reconfigure_options``).
    """
    from dynamic_reconfigure.parameter_generator_catkin import ParameterGenerator, bool_t, double_t, int_t, str_t
    params, node_name = RECONFIGURABLE[stem]
    types = {'double': double_t, 'int': int_t, 'bool': bool_t, 'str': str_t}
    gen = ParameterGenerator()
    for p in params:
        kw = {}
        if p.kind in ('double', 'int'):
            if p.minimum is not None:
                kw['min'] = int(p.minimum) if p.kind == 'int' else float(p.minimum)
            if p.maximum is not None:
                kw['max'] = int(p.maximum) if p.kind == 'int' else float(p.maximum)
        gen.add(p.name, types[p.kind], 0, p.description, p.upstream_default, **kw)
    return gen.generate('cnr_navigation', node_name, stem)
