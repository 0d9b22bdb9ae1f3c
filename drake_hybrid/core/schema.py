"""Checking a YAML text against a typed config schema before Drake's ``yaml_load_typed`` reads it.

Drake's loader checks types, but some of its messages do not name the field ("could not convert
string to float: 'abc'"), it accepts a list where a ``Dict`` belongs, and YAML itself keeps the
last of two equal keys silently. ``check_yaml_against_schema`` walks the parsed YAML with the
schema (dataclasses, Drake config structs, List, Dict, Union) and raises one ConfigError line
naming the dotted field; Drake's loader then reads the text as usual.
"""

import dataclasses
import typing
from pathlib import Path
from typing import Dict, List, Union

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


def _schema_fields(schema):
    """{field name: type} of a config dataclass or a Drake config struct (None for other types)."""
    if dataclasses.is_dataclass(schema):
        return typing.get_type_hints(schema)
    if hasattr(schema, "__fields__"):
        return {item.name: item.type for item in schema.__fields__}
    return None


def type_mismatch(value, schema, path=""):
    """The first place where the parsed YAML ``value`` does not fit ``schema``, as a one-line
    message naming the dotted field ("gains.velocity[0]: expected a number, got 'abc'"), or None."""
    where = path or "the config"
    fields = _schema_fields(schema)
    origin, arguments = typing.get_origin(schema), typing.get_args(schema)
    if fields is not None:
        if value is None:
            return None
        if not isinstance(value, dict):
            return f"{where}: expected a section (a mapping of fields), got {value!r}"
        for key, item in value.items():
            if key not in fields:
                return f"{where}: unknown field '{key}'; its fields are {', '.join(sorted(fields))}"
            found = type_mismatch(item, fields[key], f"{path}.{key}" if path else str(key))
            if found:
                return found
        return None
    if origin is Union:
        results = [type_mismatch(value, member, path) for member in arguments]
        return None if any(result is None for result in results) else results[0]
    if origin in (list, List):
        if not isinstance(value, list):
            return f"{where}: expected a list, got {value!r}"
        for index, item in enumerate(value):
            found = type_mismatch(item, arguments[0], f"{path}[{index}]")
            if found:
                return found
        return None
    if origin in (dict, Dict):
        if not isinstance(value, dict):
            return f"{where}: expected a mapping, got {value!r}"
        for key, item in value.items():
            found = type_mismatch(item, arguments[1], f"{path}.{key}")
            if found:
                return found
        return None
    if schema is bool:
        return None if isinstance(value, bool) else f"{where}: expected true or false, got {value!r}"
    if schema is int:
        return None if isinstance(value, int) and not isinstance(value, bool) else \
            f"{where}: expected an integer, got {value!r}"
    if schema is float:
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            return None
        try:
            float(value)
            return None if isinstance(value, str) else f"{where}: expected a number, got {value!r}"
        except (TypeError, ValueError):
            return f"{where}: expected a number, got {value!r}"
    if schema is str:
        return None if isinstance(value, str) else f"{where}: expected a word, got {value!r}"
    return None
