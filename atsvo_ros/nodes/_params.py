"""Every config field as a read-only ROS parameter with a descriptor (description, range), and back to a config.

The descriptors come from :mod:`atsvo_ros.config` (each field's ``doc`` and range metadata), so
``ros2 param describe /atsvo_tracking ats.tau_u_s`` shows what the offline tools validate. The values
go through the same validation as a YAML file read offline: a bad one stops the node with one line
naming the key, the value and the allowed range.
"""
from __future__ import annotations

import dataclasses
import typing
from typing import Any

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rclpy.exceptions import InvalidParameterTypeException, InvalidParameterValueException
from rclpy.node import Node
from rclpy.parameter import Parameter

from atsvo_ros.config import AtsvoConfig, config_from_dict
from atsvo_ros.errors import ConfigError


@dataclasses.dataclass(frozen=True)
class ConfigField:
    """One leaf of the config: dotted key, Python type, default and metadata."""

    key: str
    typ: Any
    default: Any
    meta: dict[str, Any]

    @property
    def is_float_list(self) -> bool:
        return typing.get_origin(self.typ) is tuple


def config_fields(cls: type = AtsvoConfig, prefix: str = "", instance: Any = None) -> list[ConfigField]:
    """The leaves of the config dataclasses, in declaration order."""
    instance = cls() if instance is None else instance
    hints = typing.get_type_hints(cls)
    out: list[ConfigField] = []
    for f in dataclasses.fields(cls):
        value = getattr(instance, f.name)
        if dataclasses.is_dataclass(value):
            out += config_fields(type(value), f"{prefix}{f.name}.", value)
        else:
            out.append(ConfigField(prefix + f.name, hints[f.name], list(value) if isinstance(value, tuple) else value,
                                   dict(f.metadata)))
    return out


def range_text(meta: dict[str, Any]) -> str:
    """``(0.0, 10.0]``, ``[1, 16]`` or ``one of: a, b`` (empty when unconstrained)."""
    if meta.get("choices"):
        return "one of: " + ", ".join(str(c) for c in meta["choices"])
    lo, hi = meta.get("lo"), meta.get("hi")
    if lo is None and hi is None:
        return ""
    left = "(" if meta.get("lo_open") else "["
    return f"{left}{'-inf' if lo is None else lo}, {'inf' if hi is None else hi}]"


def descriptor(field: ConfigField) -> ParameterDescriptor:
    """The ROS descriptor of a config field: description, range (ROS ranges are closed: an open lower end is
    checked by the config), read-only (values are applied at start)."""
    meta = field.meta
    d = ParameterDescriptor(name=field.key, description=meta.get("doc") or field.key, read_only=True)
    d.additional_constraints = range_text(meta)
    if field.key.split(".")[-1].startswith("T_"):
        d.additional_constraints = "row-major 4x4 rigid transform (16 numbers)"
    lo, hi = meta.get("lo"), meta.get("hi")
    if (lo is not None or hi is not None) and not meta.get("choices"):
        if field.typ is float:
            d.floating_point_range = [FloatingPointRange(from_value=float("-inf") if lo is None else float(lo),
                                                         to_value=float("inf") if hi is None else float(hi),
                                                         step=0.0)]
        elif field.typ is int:
            d.integer_range = [IntegerRange(from_value=-(2**63) if lo is None else int(lo),
                                            to_value=2**63 - 1 if hi is None else int(hi), step=0)]
    return d


def _normalise_override(node: Node, field: ConfigField) -> None:
    """Let YAML integers stand for doubles (``tau_u_s: 1``, ``T_base_rgb: [1, 0, ...]``), as the config loader does."""
    overrides = getattr(node, "_parameter_overrides", None)  # rclpy keeps the --params-file values here
    if not overrides or field.key not in overrides:
        return
    p = overrides[field.key]
    if field.typ is float and p.type_ == Parameter.Type.INTEGER:
        overrides[field.key] = Parameter(field.key, Parameter.Type.DOUBLE, float(p.value))
    elif field.is_float_list and p.type_ == Parameter.Type.INTEGER_ARRAY:
        overrides[field.key] = Parameter(field.key, Parameter.Type.DOUBLE_ARRAY, [float(v) for v in p.value])


def _override_value(node: Node, key: str) -> Any:
    overrides = getattr(node, "_parameter_overrides", None) or {}
    p = overrides.get(key)
    return None if p is None else p.value


def declare_config(node: Node) -> AtsvoConfig:
    """Declare every config field on ``node`` and build the validated config from the values it got.

    Raises :class:`ConfigError` (key, value, allowed range) for a bad value or an unknown key in one
    of the config's sections, exactly as loading the same file with ``load_config`` would.
    """
    fields = config_fields()
    values: dict[str, Any] = {}
    for field in fields:
        _normalise_override(node, field)
        try:
            value = node.declare_parameter(field.key, field.default, descriptor(field)).value
        except (InvalidParameterValueException, InvalidParameterTypeException):
            value = _override_value(node, field.key)  # the config's validation says what is wrong with it
        if value is None and field.is_float_list:
            value = []  # `D: []` arrives as an unset parameter
        values[field.key] = value
    sections = {f.key.split(".")[0] for f in fields if "." in f.key}
    known = {f.key for f in fields}
    for key in sorted(getattr(node, "_parameter_overrides", None) or {}):
        if key.split(".")[0] in sections and key not in known:
            section = key.split(".")[0]
            names = sorted(f.key.split(".", 1)[1] for f in fields if f.key.startswith(section + "."))
            raise ConfigError(f"unknown parameter {key} (known in {section}: {', '.join(names)})")
    return config_from_dict(values)


__all__ = ["ConfigField", "config_fields", "declare_config", "descriptor", "range_text"]
