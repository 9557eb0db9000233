"""Every estimator parameter, declared once.

One frozen dataclass tree (:mod:`.declarations`) drives the CLI (``--set group.name=value``), TOML
config files (``[group] name = value``) and the inspector's parameter panel. A parameter is declared
with :func:`param`, whose metadata (doc, unit, bounds, step) is what the CLI help, the TOML comments
and the GUI sliders show; :mod:`.specs` turns the tree into specs and checks every value coming in.
Angles are degrees here (the edge) and radians inside the estimator.
"""

from estimator.params.declarations import (
    ExtensionParams,
    GateParams,
    Method,
    NoiseParams,
    OffsetParams,
    Params,
    PseudoObsParams,
    SensorParams,
    TriggerParams,
    WindowParams,
    for_method,
    matching_params,
    param,
)
from estimator.params.specs import (
    ParamSpec,
    coerce_value,
    get_param,
    load_params,
    param_specs,
    params_to_toml,
    parse_assignments,
    save_params,
    with_values,
)

__all__ = [
    "ExtensionParams",
    "GateParams",
    "Method",
    "NoiseParams",
    "OffsetParams",
    "ParamSpec",
    "Params",
    "PseudoObsParams",
    "SensorParams",
    "TriggerParams",
    "WindowParams",
    "coerce_value",
    "for_method",
    "get_param",
    "load_params",
    "matching_params",
    "param",
    "param_specs",
    "params_to_toml",
    "parse_assignments",
    "save_params",
    "with_values",
]
