"""Vehicle parameters: the wire package's models, re-exported for the routes."""

from __future__ import annotations

from skyhelm_wire.params import (
    ParamChoiceOut,
    ParamInfoOut,
    ParamMetadataOut,
    ParamOut,
    ParamsOut,
    ParamValueBody,
)

__all__ = [
    "ParamChoiceOut",
    "ParamInfoOut",
    "ParamMetadataOut",
    "ParamOut",
    "ParamValueBody",
    "ParamsOut",
]
