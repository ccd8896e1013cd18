"""The configuration as TOML: read, checked and written in this one place.

Unknown tables or keys, values of the wrong type and the flat ``[slam]``
table of earlier versions are refused with one sentence saying what to
write instead.
"""

from __future__ import annotations

import dataclasses
import tomllib
from pathlib import Path

from helpers.config.bounds import human_size
from helpers.config.tables import STAGE_TABLES, Config, noise_seed_from_environment
from helpers.errors import SlamError
from helpers.paths import input_file

# Every key of every table with a comment each is a few kilobytes; a larger file is not a configuration,
# and reading it whole (twice: the values, then which keys were given) would take the memory and the time.
MAX_CONFIG_BYTES = 1 << 20


def load_config(path: str | Path | None = None) -> Config:
    """Read a TOML configuration; no path gives the defaults. Unless the file
    sets ``[sensor] seed``, the seed is
    :func:`~helpers.config.tables.noise_seed_from_environment`'s (the CLI's entry)."""
    if path is None:
        return Config().with_values(sensor={"seed": noise_seed_from_environment()})
    path = input_file(path, "config file")
    size = path.stat().st_size
    if size > MAX_CONFIG_BYTES:
        raise SlamError(
            f"config file {path} is {human_size(size)}; a configuration is a few kilobytes "
            f"(the limit is {human_size(MAX_CONFIG_BYTES)})"
        )
    try:
        data = tomllib.loads(_read_text(path))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise SlamError(f"config file {path} is not valid TOML: {exc}") from None
    except RecursionError:
        raise SlamError(f"config file {path} nests its values too deeply") from None
    config = config_from_dict(data, source=str(path))
    if "seed" in data.get("sensor", {}):  # config_from_dict has checked that [sensor] is a table
        return config
    return config.with_values(sensor={"seed": noise_seed_from_environment()})


def config_from_dict(data: dict, source: str = "config") -> Config:
    """Build a :class:`Config` from nested dictionaries, refusing unknown keys."""
    if "slam" in data:
        raise SlamError(f"{source}: {_moved(data['slam'])}")
    unknown = sorted(set(data) - set(STAGE_TABLES))
    if unknown:
        raise SlamError(f"{source}: unknown table(s) {unknown}; known tables are {list(STAGE_TABLES)}")
    tables = {}
    for f in dataclasses.fields(Config):
        table = data.get(f.name, {})
        if not isinstance(table, dict):
            raise SlamError(f"{source}: [{f.name}] must be a table")
        tables[f.name] = _build(f.default_factory, table, f"{source} [{f.name}]")
    return Config(**tables)


def given_keys(path: str | Path | None) -> frozenset[tuple[str, str]]:
    """The ``(table, key)`` pairs a TOML file sets (none without a file); read after :func:`load_config`."""
    if path is None:
        return frozenset()
    data = tomllib.loads(_read_text(Path(path)))
    return frozenset((table, key) for table, values in data.items() for key in values)


def _read_text(path: Path) -> str:
    """A TOML file's text: UTF-8, as TOML is, with the byte-order mark some editors write first taken away."""
    return path.read_text(encoding="utf-8-sig")


def config_to_dict(config: Config, tables=STAGE_TABLES) -> dict:
    """The configuration (or some of its tables) as plain nested dictionaries, for JSON or TOML."""
    return {name: _plain(dataclasses.asdict(getattr(config, name))) for name in tables}


def config_to_toml(config: Config, tables=STAGE_TABLES, title: str | None = None) -> str:
    """The configuration (or some of its tables) as TOML that :func:`load_config` reads back."""
    lines = [f"# {title}"] if title else []
    for table, values in config_to_dict(config, tables).items():
        lines.append(f"[{table}]")
        lines.extend(f"{key} = {_toml_value(value)}" for key, value in values.items())
        lines.append("")
    return "\n".join(lines)


def _moved(old) -> str:
    """The error for an earlier version's flat ``[slam]`` table: where each of its keys went."""
    homes = {f.name: table for table in STAGE_TABLES[1:] for f in dataclasses.fields(getattr(Config(), table))}
    keys = list(old) if isinstance(old, dict) else []
    moves = [f"{key} -> [{homes[key]}] {key}" for key in keys if key in homes]
    where = "; ".join(moves) if moves else f"use the tables {list(STAGE_TABLES[1:])}"
    return f"the [slam] table is now split by stage: {where}"


def _toml_value(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return '"' + value.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(value, list):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    return repr(value)


def _build(cls, table: dict, where: str):
    defaults = cls()
    known = [f.name for f in dataclasses.fields(cls)]
    unknown = sorted(set(table) - set(known))
    if unknown:
        raise SlamError(f"{where}: unknown key(s) {unknown}; known keys are {sorted(known)}")
    return cls(**{key: _coerce(value, getattr(defaults, key), f"{where} {key}") for key, value in table.items()})


def _coerce(value, default, where: str):
    """Give ``value`` the type of ``default``, or explain why it cannot have it."""
    if isinstance(default, bool):
        if not isinstance(value, bool):
            raise SlamError(f"{where} must be true or false, got {value!r}")
        return value
    if isinstance(default, int):
        if isinstance(value, bool) or not isinstance(value, int) or not -(2**63) <= value < 2**63:
            raise SlamError(f"{where} must be a 64-bit integer, got {value!r}")
        return value
    if isinstance(default, float):
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise SlamError(f"{where} must be a number, got {value!r}")
        try:
            return float(value)
        except OverflowError:  # an integer beyond any float
            raise SlamError(f"{where} is too large a number") from None
    if isinstance(default, tuple):
        if not isinstance(value, list) or len(value) != len(default):
            raise SlamError(f"{where} must be a list of {len(default)} numbers, got {value!r}")
        return tuple(_coerce(v, d, where) for v, d in zip(value, default, strict=True))
    if isinstance(default, str):
        if not isinstance(value, str):
            raise SlamError(f"{where} must be a string, got {value!r}")
        return value
    raise TypeError(f"no coercion for {type(default).__name__}")  # a bug, not user input


def _plain(value):
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, tuple):
        return [_plain(v) for v in value]
    return value
