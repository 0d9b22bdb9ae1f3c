"""Checking a config against its typed schema: a YAML text before Drake's ``yaml_load_typed`` reads
it, and a config built or changed in Python before it is used, by the same rules.

Drake's loader checks types, but some of its messages do not name the field ("could not convert
string to float: 'abc'"), it accepts a list where a ``Dict`` belongs, and YAML itself keeps the
last of two equal keys silently. ``check_yaml_against_schema`` walks the parsed YAML with the
schema (dataclasses, Drake config structs, List, Dict, Union) and raises one ConfigError line
naming the dotted field; Drake's loader then reads the text as usual. A dataclass built in Python
has no loader: ``check_types`` walks its fields with the same ``type_mismatch`` (a bool is not a
number, a string not a bool, a section is its dataclass), which ``ScenarioConfig.validate`` runs
first.
"""

import dataclasses
import functools
import numbers
import typing
from pathlib import Path
from typing import Dict, List, Union

import numpy as np
import yaml

from drake_hybrid.core.errors import ConfigError


class _UniqueKeyLoader(getattr(yaml, "CSafeLoader", yaml.SafeLoader)):
    """A YAML loader that refuses a key given twice in one mapping (and accepts any !Tag). It parses
    with libyaml when PyYAML has it (a sweep point's config: 0.3 s in pure Python, a few ms)."""

    def construct_mapping(self, node, deep=False):
        seen = set()
        for key_node, _ in node.value:
            key = self.construct_object(key_node, deep=deep)
            if key in seen:
                raise ConfigError(f"the key '{key}' is given twice (line {key_node.start_mark.line + 1}); "
                                  "YAML would silently keep the last one")
            seen.add(key)
        return super().construct_mapping(node, deep=deep)


_UniqueKeyLoader.add_multi_constructor("!", lambda loader, suffix, node: (
    loader.construct_mapping(node) if isinstance(node, yaml.MappingNode) else None))


MAX_YAML_SIZE = 1_000_000     # characters of a YAML file the package reads (a config, a sweep spec, a task file)


def read_yaml_file(path, what, error=ConfigError, max_size=MAX_YAML_SIZE):
    """The text of the YAML file ``path``; ``error`` (one line, naming ``what`` and the path) if it does
    not exist, is a directory, cannot be read, is not UTF-8 text (a binary file), is larger than
    ``max_size`` characters or holds nothing but whitespace and comments."""
    path = Path(path)
    if path.is_dir():
        raise error(f"{what} '{path}' is a directory, not a YAML file")
    if not path.exists():
        raise error(f"{what} '{path}' does not exist")
    try:
        data = path.read_bytes()
    except OSError as problem:
        raise error(f"{what} '{path}' cannot be read ({problem.strerror or type(problem).__name__})") from None
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as problem:
        raise error(f"{what} '{path}' is not UTF-8 text (a binary file?): byte 0x{data[problem.start]:02x} at "
                    f"offset {problem.start}") from None
    if len(text) > max_size:
        raise error(f"{what} '{path}' is larger than {max_size // 1000} kB")
    if not any(line.split("#", 1)[0].strip() for line in text.splitlines()):
        raise error(f"{what} '{path}' is empty (no YAML mapping, only whitespace or comments)")
    return text


MAX_YAML_DEPTH = 100         # levels of [ and { a YAML text may nest (a config needs fewer than ten)


def nesting_depth(text, opening="[{", closing="]}"):
    """The deepest nesting of the ``opening`` brackets in ``text`` (a linear scan, before any parsing;
    YAML's flow collections by default)."""
    depth = deepest = 0
    for character in text:
        if character in opening:
            depth += 1
            deepest = max(deepest, depth)
        elif character in closing:
            depth -= 1
    return deepest


def check_depth(text, where="", error=ConfigError):
    """``error`` if ``text`` nests [ and { deeper than MAX_YAML_DEPTH: refused before a parser recurses into it."""
    if isinstance(text, str) and nesting_depth(text) > MAX_YAML_DEPTH:
        raise error(f"{where}the YAML nests too deeply (more than {MAX_YAML_DEPTH} levels of [ and {{)")


def check_yaml_against_schema(text, schema, where="", error=ConfigError):
    """``error`` (one line, prefixed by ``where``) for a text that nests too deeply (``check_depth``), a
    repeated key, invalid YAML, or a value that does not fit ``schema`` (``type_mismatch``); returns the
    parsed YAML."""
    check_depth(text, where, error)
    try:
        parsed = yaml.load(text, Loader=_UniqueKeyLoader)
    except ConfigError as problem:
        raise error(f"{where}{problem}") from None
    except yaml.YAMLError as problem:
        if "maximum nesting depth" in str(problem):     # libyaml's limit (PyYAML's own parser recurses instead)
            raise error(f"{where}the YAML nests too deeply") from None
        raise error(f"{where}not valid YAML: {str(problem).splitlines()[0]}") from None
    mismatch = type_mismatch(parsed, schema)
    if mismatch:
        raise error(f"{where}{mismatch}")
    return parsed


@functools.lru_cache(maxsize=None)
def _schema_fields(schema):
    """{field name: type} of a config dataclass or a Drake config struct (None for other types)."""
    if isinstance(schema, type) and dataclasses.is_dataclass(schema):
        hints = typing.get_type_hints(schema)
        return {item.name: hints[item.name] for item in dataclasses.fields(schema)}
    if hasattr(schema, "__fields__"):
        return {item.name: item.type for item in schema.__fields__}
    return None


def unknown_field(schema, names, where):
    """The message for the first of ``names`` that is not a field of ``schema`` ("path: unknown field
    'spede'; its fields are ..."), or None: what the YAML loader says of an unknown key, and
    ``ScenarioConfig.replace`` and ``with_path`` of an unknown keyword."""
    fields = _schema_fields(schema)
    for name in names:
        if name not in fields:
            return f"{where}: unknown field '{name}'; its fields are {', '.join(sorted(fields))}"
    return None


def _shown(value, parsed):
    """``value`` for a message: its repr (a Python object's cut to 80 characters, with its type where the
    repr does not say it)."""
    if parsed:
        return repr(value)
    text = repr(value)
    text = text if len(text) <= 80 else text[:77] + "..."
    if value is None or isinstance(value, (bool, int, float, str, list)):
        return text
    return f"{text} (a {type(value).__name__})"


def _is_sequence(value, parsed):
    """A YAML list; in Python also a tuple or a 1-D numpy array."""
    if parsed:
        return isinstance(value, list)
    return isinstance(value, (list, tuple)) or (isinstance(value, np.ndarray) and value.ndim == 1)


def _is_number(value, parsed):
    """A real number and not a bool. Parsed YAML: also a string Drake's loader reads as one (YAML 1.1
    reads an unquoted 1e6 as a string); in Python a string is refused, not parsed."""
    if isinstance(value, (bool, np.bool_)):
        return False
    if isinstance(value, numbers.Real):
        return True
    if not (parsed and isinstance(value, str)):
        return False
    try:
        float(value)
    except ValueError:
        return False
    return True


def type_mismatch(value, schema, path="", parsed=True):
    """The first place where ``value`` does not fit ``schema``, as a one-line message naming the dotted
    field ("gains.velocity[0]: expected a number, got 'abc'"), or None.

    ``parsed``: ``value`` is parsed YAML (a section is a mapping of fields, None an empty section).
    Otherwise ``value`` is the Python object a config holds (``ScenarioConfig.validate``): a section
    must be an instance of its dataclass (a dict is refused, naming the class to build it with), a
    list may also be a tuple or a 1-D numpy array, and a string is not a number. The rules per type
    are the same: a bool is not a number, a number or a string is not a bool."""
    where = path or "the config"
    fields = _schema_fields(schema)
    origin, arguments = typing.get_origin(schema), typing.get_args(schema)
    if fields is not None:
        if parsed:
            if value is None:
                return None
            if not isinstance(value, dict):
                return f"{where}: expected a section (a mapping of fields), got {value!r}"
            items = value.items()
        else:
            if not isinstance(value, schema):
                return _section_mismatch(value, (schema,), where)
            items = ((name, getattr(value, name)) for name in fields)
        for key, item in items:
            found = unknown_field(schema, [key], where) or type_mismatch(item, fields[key], f"{path}.{key}" if path else str(key), parsed)
            if found:
                return found
        return None
    if origin is Union:
        if not parsed:
            sections = [member for member in arguments if _schema_fields(member) is not None]
            chosen = [member for member in sections if isinstance(value, member)]
            if chosen:
                return type_mismatch(value, chosen[0], path, parsed)
            if sections and len(sections) == len(arguments):
                return _section_mismatch(value, sections, where)
        results = [type_mismatch(value, member, path, parsed) for member in arguments]
        return None if any(result is None for result in results) else results[0]
    if origin in (list, List):
        if not _is_sequence(value, parsed):
            return f"{where}: expected a list, got {_shown(value, parsed)}"
        for index, item in enumerate(value):
            found = type_mismatch(item, arguments[0], f"{path}[{index}]", parsed)
            if found:
                return found
        return None
    if origin in (dict, Dict):
        if not isinstance(value, dict):
            return f"{where}: expected a mapping, got {_shown(value, parsed)}"
        for key, item in value.items():
            if not parsed and not isinstance(key, str):
                return f"{where}: expected a mapping of names (str), got the key {key!r}"
            found = type_mismatch(item, arguments[1], f"{path}.{key}", parsed)
            if found:
                return found
        return None
    if schema is bool:
        allowed = (bool,) if parsed else (bool, np.bool_)
        return None if isinstance(value, allowed) else f"{where}: expected true or false, got {_shown(value, parsed)}"
    if schema is int:
        return None if isinstance(value, numbers.Integral) and not isinstance(value, (bool, np.bool_)) else \
            f"{where}: expected an integer, got {_shown(value, parsed)}"
    if schema is float:
        return None if _is_number(value, parsed) else f"{where}: expected a number, got {_shown(value, parsed)}"
    if schema is str:
        return None if isinstance(value, str) else f"{where}: expected a word, got {_shown(value, parsed)}"
    return None


def _section_mismatch(value, kinds, where):
    names = " or ".join(f"a {kind.__name__}" for kind in kinds)
    return (f"{where}: expected {names}, got {_shown(value, False)}; build the section with "
            f"{' or '.join(f'{kind.__name__}(...)' for kind in kinds)}")


def check_types(config, schema=None, where="", error=ConfigError):
    """``config`` (a config dataclass built or changed in Python) if every field holds a value of its
    declared type, by the YAML loader's rules (``type_mismatch``); else ``error`` naming the first
    field that does not. ``schema``: the type ``config`` must be (default: its own)."""
    mismatch = type_mismatch(config, schema or type(config), where, parsed=False)
    if mismatch:
        raise error(mismatch)
    return config
