"""Reading a file the user names, one way for every kind: configs, scenarios, subgoals, thresholds,
relations and a run folder's own files.

- A path is opened only when it is a regular file: a FIFO would block for ever and /dev/zero never ends.
- Each kind has a size bound, checked before reading and again while reading (the file may grow between).
- Bytes are decoded as UTF-8 (a BOM allowed); an undecodable file is named with the byte where it fails.
- TOML, YAML and JSON are parsed with their nesting bounded (``MAX_NESTING``). A parser's recursion error
  becomes a one-line error. YAML aliases may expand to at most ``MAX_NODES`` values, which stops a
  "billion laughs" document; merge keys (``<<``) may copy at most as many entries, and an integer scalar
  longer than ``MAX_INT_CHARS`` is refused before it is built (its digits, or the parts of a base-60
  ``1:2:3``, cost time growing with their square).
- Numbers go through :func:`check_number`: a bool or a string is refused, an integer too large for a float
  is refused before any conversion, and the value must be finite and within its physical range.
- Every error is a :class:`ConfigError` of one line naming the file. A value is quoted through
  :func:`brief`, so a message stays short whatever the value.
"""

from __future__ import annotations

import functools
import json
import math
import reprlib
import tomllib
from collections.abc import Callable
from pathlib import Path
from typing import Any

from ..errors import ConfigError, one_line
from .base import special_file_kind

__all__ = [
    "MAX_NESTING", "MAX_NODES", "brief", "check_number", "check_regular_file", "load_json",
    "load_toml", "load_yaml", "parse_yaml", "read_bytes", "read_text",
]

MAX_NESTING = 64
"""Deepest nesting of lists and tables accepted in a TOML, YAML or JSON file."""
MAX_NODES = 1_000_000
"""Most values a parsed document may hold, each alias counted as often as it is used."""
MAX_INT_DIGITS = 30
"""An integer with more decimal digits is refused before any conversion (no physical value needs them)."""
_INT_LIMIT = int("1" + "0" * MAX_INT_DIGITS)  # 10**MAX_INT_DIGITS (the package allows only literal powers)
_LOG10_2 = 0.30102999566398120  # digits per bit
MAX_INT_CHARS = 1000
"""Longest integer scalar a YAML document may hold (far above MAX_INT_DIGITS, so its error names the key)."""

_BRIEF = reprlib.Repr()
_BRIEF.maxlevel, _BRIEF.maxdict, _BRIEF.maxlist, _BRIEF.maxtuple = 2, 4, 4, 4
_BRIEF.maxstring, _BRIEF.maxother, _BRIEF.maxlong = 40, 40, 40


def brief(value: Any) -> str:
    """A short repr for an error message: containers cut after a few items and two levels, long strings
    and integers cut in the middle (an alias bomb or a 10,000-digit integer prints in a line)."""
    if isinstance(value, int) and not isinstance(value, bool) and abs(value) >= _INT_LIMIT:
        return f"an integer of {_digits(abs(value))} digits"
    try:
        return _BRIEF.repr(value)
    except (ValueError, RecursionError):  # an int beyond Python's str() limit deep inside a container
        return f"a {type(value).__name__}"


def _digits(n: int) -> int:
    """Decimal digits of n > 0 without str() (which refuses more than 4,300 digits)."""
    d = int(n.bit_length() * _LOG10_2) + 1  # right, or one too many
    return d - 1 if n < pow(10, d - 1) else d


def check_regular_file(path: Path, what: str, max_bytes: int) -> int:
    """The size of ``path`` if it is a regular file of at most ``max_bytes``, without opening it.

    Raises:
        ConfigError: missing, a folder, a FIFO / device / socket, unreadable, or too large; one line
        naming the path and ``what`` it should be ("config file").
    """
    if (kind := special_file_kind(path)) is not None:
        raise ConfigError(f"{path}: is {kind}, not a {what} (never opened)")
    try:
        st = path.stat()
    except FileNotFoundError:
        raise ConfigError(f"{path}: {what} not found") from None
    except OSError as e:
        raise ConfigError(f"{path}: cannot read the {what}: {one_line(e, 300)}") from None
    if path.is_dir():
        raise ConfigError(f"{path}: is a folder, not a {what}")
    if st.st_size > max_bytes:
        raise ConfigError(f"{path}: {st.st_size} bytes, more than the {_size(max_bytes)} a {what} may have")
    return st.st_size


def _size(n: int) -> str:
    return f"{n >> 20} MB" if n >= 1 << 20 else f"{n >> 10} KB" if n >= 1 << 10 else f"{n} bytes"


def read_bytes(path: Path, what: str, max_bytes: int) -> bytes:
    """The whole content of a regular file of at most ``max_bytes`` (see :func:`check_regular_file`)."""
    path = Path(path)
    check_regular_file(path, what, max_bytes)
    try:
        with path.open("rb") as f:
            data = f.read(max_bytes + 1)
    except FileNotFoundError:
        raise ConfigError(f"{path}: {what} not found") from None
    except OSError as e:
        raise ConfigError(f"{path}: cannot read the {what}: {one_line(e, 300)}") from None
    if len(data) > max_bytes:
        raise ConfigError(f"{path}: more than the {_size(max_bytes)} a {what} may have (it grew while read)")
    return data


def read_text(path: Path, what: str, max_bytes: int) -> str:
    """:func:`read_bytes` decoded as UTF-8 (a leading BOM is dropped)."""
    data = read_bytes(path, what, max_bytes)
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as e:
        line = data.count(b"\n", 0, e.start) + 1
        raise ConfigError(f"{path}: line {line}: not UTF-8 text (byte {e.start}: "
                          f"{data[e.start]:#04x})") from None


def _check_shape(doc: Any, where: str) -> None:
    """Refuse a document nested deeper than MAX_NESTING, holding more than MAX_NODES values (aliases
    counted as expanded) or containing itself, without recursion and in time proportional to its distinct
    containers."""
    done: dict[int, tuple[int, int]] = {}  # id -> (values, nesting) of a container fully measured
    open_: set[int] = set()  # containers whose children are being measured
    stack: list[tuple[Any, bool]] = [(doc, False)]
    while stack:
        obj, children_done = stack.pop()
        if not isinstance(obj, dict | list | tuple) or (id(obj) in done and not children_done):
            continue
        children = [c for c in (obj.values() if isinstance(obj, dict) else obj)
                    if isinstance(c, dict | list | tuple)]
        if children_done:
            open_.discard(id(obj))
            size = 1 + len(obj) - len(children) + sum(done[id(c)][0] for c in children)
            nesting = 1 + max((done[id(c)][1] for c in children), default=0)
            if size > MAX_NODES:
                raise ConfigError(f"{where}: more than {MAX_NODES:,} values (aliases counted as expanded)")
            if nesting > MAX_NESTING:
                raise ConfigError(f"{where}: nested more than {MAX_NESTING} levels deep")
            done[id(obj)] = (size, nesting)
            continue
        if id(obj) in open_:
            raise ConfigError(f"{where}: a value contains itself (a recursive alias)")
        open_.add(id(obj))
        stack.append((obj, True))
        for c in children:
            if id(c) in open_:
                raise ConfigError(f"{where}: a value contains itself (a recursive alias)")
            if id(c) not in done:
                stack.append((c, False))
        if len(open_) > MAX_NESTING:
            raise ConfigError(f"{where}: nested more than {MAX_NESTING} levels deep")


def _load(path: Path, what: str, max_bytes: int, parse: Callable[[str], Any], kind: str) -> Any:
    """Read ``path`` as text and ``parse`` it; a parse error (the decoders' errors and an integer beyond
    Python's str() limit are ValueErrors) or a parser's recursion error is one line naming the file."""
    text = read_text(path, what, max_bytes)
    try:
        doc = parse(text)
    except RecursionError:
        raise ConfigError(f"{path}: nested more than {MAX_NESTING} levels deep") from None
    except ValueError as e:
        raise ConfigError(f"{path}: not {kind}: {one_line(e, 300)}") from None
    _check_shape(doc, str(path))
    return doc


def load_toml(path: Path, what: str, max_bytes: int) -> dict[str, Any]:
    """A TOML file as a dict (see the module docstring for the bounds)."""
    doc: dict[str, Any] = _load(path, what, max_bytes, tomllib.loads, "a valid TOML file")
    return doc


@functools.cache
def _yaml_loader() -> type:
    """yaml.SafeLoader bounding what a short document can make it build: integer scalars of at most
    MAX_INT_CHARS characters, and merge keys copying at most MAX_NODES entries in all (a chain of mappings
    each merging the previous one grows with the square of its length)."""
    import yaml
    from yaml.constructor import ConstructorError

    class Loader(yaml.SafeLoader):
        merged = 0

        def construct_yaml_int(self, node: Any) -> int:
            if len(node.value) > MAX_INT_CHARS:
                raise ConstructorError(None, None, f"an integer of {len(node.value)} characters (at most "
                                       f"{MAX_INT_CHARS})", node.start_mark)
            return int(super().construct_yaml_int(node))

        def flatten_mapping(self, node: Any) -> None:
            merges = any(k.tag == "tag:yaml.org,2002:merge" for k, _ in node.value)
            super().flatten_mapping(node)
            if merges:
                self.merged += len(node.value)
                if self.merged > MAX_NODES:
                    raise ConstructorError(None, None, f"merge keys (<<) copy more than {MAX_NODES:,} "
                                           "entries", node.start_mark)

    Loader.add_constructor("tag:yaml.org,2002:int", Loader.construct_yaml_int)
    return Loader


def parse_yaml(text: str, where: str) -> Any:
    """A YAML document (safe types only) from text; ``where`` names it in errors."""
    import yaml

    try:
        doc = yaml.load(text, Loader=_yaml_loader())
    except yaml.YAMLError as e:
        raise ConfigError(f"{where}: not valid YAML: {one_line(e, 300)}") from None
    except RecursionError:
        raise ConfigError(f"{where}: nested more than {MAX_NESTING} levels deep") from None
    except (ValueError, OverflowError) as e:  # a date out of range (2024-13-01), a number beyond str()
        raise ConfigError(f"{where}: not valid YAML: {one_line(e, 300)}") from None
    _check_shape(doc, where)
    return doc


def load_yaml(path: Path, what: str, max_bytes: int) -> Any:
    """A YAML file (see :func:`parse_yaml`)."""
    return parse_yaml(read_text(path, what, max_bytes), str(path))


def load_json(path: Path, what: str, max_bytes: int) -> Any:
    """A JSON file (see the module docstring for the bounds)."""
    return _load(path, what, max_bytes, json.loads, "valid JSON")


def check_number(value: Any, where: str, lo: float = -math.inf, hi: float = math.inf) -> float:
    """``value`` as a float when it is a number (not a bool), finite and within [lo, hi].

    An integer of more than MAX_INT_DIGITS digits is refused before it is converted (float() of a 400-digit
    integer raises OverflowError; one of 5,000 digits cannot even be printed).

    Raises:
        ConfigError: "<where>: must be a number ..." in one line.
    """
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ConfigError(f"{where}: must be a number, got {brief(value)}")
    if isinstance(value, int) and abs(value) >= _INT_LIMIT:
        raise ConfigError(f"{where}: must be a number from {lo:g} to {hi:g}, got {brief(value)}")
    x = float(value)
    if not math.isfinite(x):
        raise ConfigError(f"{where}: must be finite, got {x!r}")
    if not lo <= x <= hi:
        raise ConfigError(f"{where}: must be from {lo:g} to {hi:g}, got {x:g}")
    return x
