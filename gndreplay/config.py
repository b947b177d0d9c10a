"""Run configuration: frozen sections per stage, presets, and TOML loading with validation.

Stage-specific parameter dataclasses live next to the code that uses them (model, scanmatch, nf1, nd,
supervisor) so a stage receives only its own section; this module composes them into one ``Config``,
owns the presets and the TOML loader (unknown keys and wrong types are errors naming the key and file).
"""

from __future__ import annotations

import dataclasses
import json
import tomllib
import types
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal, Union, get_args, get_origin, get_type_hints

from .errors import ConfigError
from .pipeline.model import GRID_200, GRID_400, GridParams
from .pipeline.nd import NdParams
from .pipeline.nf1 import Nf1Params
from .pipeline.stack import StackParams
from .pipeline.supervisor import SupervisorParams
from .robot import WHEELCHAIR_LASER, WHEELCHAIR_ROBOT, XR4000_LASER, XR4000_ROBOT, LaserConfig, RobotConfig
from .scanmatch import IdcParams, KissParams

__all__ = [
    "PRESETS",
    "Config",
    "CspaceConfig",
    "LaserConfig",
    "RobotConfig",
    "ScanMatchConfig",
    "apply_overrides",
    "config_to_dict",
    "config_to_toml",
    "load_config",
    "preset",
]


@dataclass(frozen=True, slots=True)
class CspaceConfig:
    """How the planner's configuration space is made from the grid.

    Attributes:
        margin_m: added to the robot's inner radius when dilating obstacles [m].
        unknown_is_free: plan through UNKNOWN cells (**choice**, GND: the environment is discovered as the
            robot goes).
    """

    margin_m: float = 0.05
    unknown_is_free: bool = True


@dataclass(frozen=True, slots=True)
class ScanMatchConfig:
    """Which matcher corrects odometry, and its settings."""

    method: Literal["idc", "kiss-icp", "odom"] = "idc"
    idc: IdcParams = IdcParams()
    kiss: KissParams = KissParams()


@dataclass(frozen=True, slots=True)
class Config:
    """The resolved configuration of a run: one frozen section per stage (pickles for batch workers)."""

    preset: str = "wheelchair"
    robot: RobotConfig = WHEELCHAIR_ROBOT
    laser: LaserConfig = WHEELCHAIR_LASER
    grid: GridParams = GRID_400
    cspace: CspaceConfig = CspaceConfig()
    planner: Nf1Params = Nf1Params()
    reactor: NdParams = NdParams()
    supervisor: SupervisorParams = SupervisorParams()
    scanmatch: ScanMatchConfig = ScanMatchConfig()

    def stack_params(self) -> StackParams:
        """The sections the navigation stack needs."""
        return StackParams(
            robot=self.robot,
            grid=self.grid,
            planner=self.planner,
            reactor=self.reactor,
            supervisor=self.supervisor,
            cspace_margin_m=self.cspace.margin_m,
            unknown_is_free=self.cspace.unknown_is_free,
        )


PRESETS: dict[str, Config] = {
    # the wheelchair paper: 1.2 x 0.7 m, differential drive, laser 0.72 m ahead of the axle,
    # (vmax, wmax) = (0.3 m/s, 0.5 rad/s), 400 x 400 x 0.05 m grid, time-outs 0.05 / 0.08 / 0.02 s
    "wheelchair": Config(),
    # GND on the Nomadic XR4000: circular holonomic base, 10 x 10 m grid of 5 cm cells
    "xr4000": Config(preset="xr4000", robot=XR4000_ROBOT, laser=XR4000_LASER, grid=GRID_200),
}


def preset(name: str) -> Config:
    """A named preset; ConfigError lists the known names."""
    try:
        return PRESETS[name]
    except KeyError:
        raise ConfigError(f"unknown preset {name!r}; known: {', '.join(sorted(PRESETS))}") from None


# --------------------------------------------------------------------------------------------------
# TOML: load with validation, dump the resolved configuration


def _check_value(value: Any, tp: Any, where: str) -> Any:
    """Validate one TOML value against a field type; returns the value converted (int -> float)."""
    origin = get_origin(tp)
    if origin is Literal:
        if value not in get_args(tp):
            allowed = ", ".join(repr(a) for a in get_args(tp))
            raise ConfigError(f"{where}: expected one of {allowed}, got {value!r}")
        return value
    if origin in (types.UnionType, Union):
        errors = []
        for alt in get_args(tp):
            if alt is type(None):
                continue
            try:
                return _check_value(value, alt, where)
            except ConfigError as err:
                errors.append(str(err))
        raise ConfigError(errors[0] if errors else f"{where}: unexpected value {value!r}")
    if tp is bool:
        if not isinstance(value, bool):
            raise ConfigError(f"{where}: expected true or false, got {value!r}")
        return value
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(f"{where}: expected an integer, got {value!r}")
        return value
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ConfigError(f"{where}: expected a number, got {value!r}")
        return float(value)
    if tp is str:
        if not isinstance(value, str):
            raise ConfigError(f"{where}: expected a string, got {value!r}")
        return value
    if dataclasses.is_dataclass(tp):
        if not isinstance(value, dict):
            raise ConfigError(f"{where}: expected a table [{where}], got {value!r}")
        return value
    raise ConfigError(f"{where}: unsupported setting type {tp!r}")  # pragma: no cover


def _override(obj: Any, table: dict[str, Any], prefix: str) -> Any:
    """A copy of dataclass ``obj`` with the keys of ``table`` replaced, validated recursively."""
    hints = get_type_hints(type(obj))
    names = {f.name for f in dataclasses.fields(obj)}
    changes: dict[str, Any] = {}
    for key, value in table.items():
        where = f"{prefix}.{key}" if prefix else key
        if key not in names:
            known = ", ".join(sorted(names))
            raise ConfigError(f"unknown key {where!r} (known in [{prefix or 'top level'}]: {known})")
        tp = hints[key]
        checked = _check_value(value, tp, where)
        if dataclasses.is_dataclass(tp):
            checked = _override(getattr(obj, key), checked, where)
        changes[key] = checked
    try:
        return dataclasses.replace(obj, **changes)
    except (ValueError, TypeError, ConfigError) as err:
        raise ConfigError(f"[{prefix or 'top level'}] {err}") from None


def apply_overrides(base: Config, table: dict[str, Any]) -> Config:
    """``base`` with a nested dict of overrides applied (unknown keys / wrong types: ConfigError)."""
    table = dict(table)
    table.pop("preset", None)
    return _override(base, table, "")


def load_config(path: Path | None = None, *, preset_name: str | None = None) -> Config:
    """The resolved config: a preset (file's ``preset`` key, else ``preset_name``, else wheelchair)
    with the TOML file's tables applied. Errors name the file and the key."""
    table: dict[str, Any] = {}
    if path is not None:
        try:
            with open(path, "rb") as f:
                table = tomllib.load(f)
        except FileNotFoundError:
            raise ConfigError(f"{path}: config file not found") from None
        except (OSError, tomllib.TOMLDecodeError) as err:
            raise ConfigError(f"{path}: not a valid TOML file: {err}") from None
    name = preset_name or table.get("preset") or "wheelchair"
    if not isinstance(name, str):
        raise ConfigError(f"{path}: preset: expected a string, got {name!r}")
    if preset_name and table.get("preset") not in (None, preset_name):
        raise ConfigError(f"{path}: preset {table['preset']!r} conflicts with --preset {preset_name}")
    try:
        cfg = apply_overrides(preset(name), table)
    except ConfigError as err:
        raise ConfigError(f"{path}: {err}" if path else str(err)) from None
    return dataclasses.replace(cfg, preset=name)


def config_to_dict(cfg: Any) -> dict[str, Any]:
    """Nested plain dict of a (config) dataclass, for JSON."""
    return dataclasses.asdict(cfg)


def _toml_value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int | float):
        return repr(v)
    return json.dumps(v)


def config_to_toml(cfg: Config) -> str:
    """The resolved configuration as TOML that ``load_config`` reads back to an equal Config."""
    lines = [f"# gndreplay resolved configuration\npreset = {json.dumps(cfg.preset)}\n"]

    def section(obj: Any, name: str) -> None:
        scalars, tables = [], []
        for f in dataclasses.fields(obj):
            v = getattr(obj, f.name)
            if dataclasses.is_dataclass(v):
                tables.append((f.name, v))
            elif v is not None:  # None means "derived default": leave the key out
                scalars.append(f"{f.name} = {_toml_value(v)}")
        lines.append(f"\n[{name}]\n" + "\n".join(scalars) + "\n")
        for sub, v in tables:
            section(v, f"{name}.{sub}")

    for f in dataclasses.fields(cfg):
        v = getattr(cfg, f.name)
        if dataclasses.is_dataclass(v):
            section(v, f.name)
    return "".join(lines)
