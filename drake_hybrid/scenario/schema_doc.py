"""The task-file schema as a Markdown table, generated from the types (not written twice).

Every field of the task file (``scenario.data_task.TaskFile``) and of the ``ScenarioConfig`` it
embeds, by dotted name, with its type, its default and the comment written next to it in the
source (where units are given). ``docs/task_files.md`` is this module's output::

    python -m drake_hybrid.scenario.schema_doc > docs/task_files.md

(``tests/test_task_files.py`` checks that the file is up to date.)
"""

import dataclasses
import inspect
import re
import typing

from drake_hybrid.scenario.data_task import TaskFile

_FIELD_LINE = re.compile(r"^\s+(\w+)\s*:\s*[^#]*?(?:#\s*(.*))?$")
# Drake's own types: documented by Drake, shown by name (and not expanded).
_DRAKE_LINKS = {
    "ModelDirective": "https://drake.mit.edu/doxygen_cxx/structdrake_1_1multibody_1_1parsing_1_1_model_directive.html",
    "Transform": "https://drake.mit.edu/doxygen_cxx/classdrake_1_1schema_1_1_transform.html",
    "MultibodyPlantConfig": "https://drake.mit.edu/doxygen_cxx/structdrake_1_1multibody_1_1_multibody_plant_config.html",
    "SimulatorConfig": "https://drake.mit.edu/doxygen_cxx/structdrake_1_1systems_1_1_simulator_config.html",
}


def field_comments(cls):
    """{field name: the comment on its line in the class's source} of a dataclass."""
    comments = {}
    try:
        source = inspect.getsource(cls)
    except (OSError, TypeError):
        return comments
    for line in source.splitlines():
        match = _FIELD_LINE.match(line)
        if match and match.group(2):
            comments.setdefault(match.group(1), match.group(2).strip())
    return comments


def type_name(kind):
    """A short readable name of a field type (List[float], Dict[str, float], A | B)."""
    origin, arguments = typing.get_origin(kind), typing.get_args(kind)
    if origin is typing.Union:
        return " | ".join(type_name(argument) for argument in arguments)
    if origin in (list, typing.List):
        return f"List[{type_name(arguments[0])}]"
    if origin in (dict, typing.Dict):
        return f"Dict[{', '.join(type_name(argument) for argument in arguments)}]"
    return getattr(kind, "__name__", str(kind))


def _summary(kind):
    """The first line of a class's own docstring ('' for a dataclass without one)."""
    text = (kind.__doc__ or "").strip()
    return "" if text.startswith(f"{kind.__name__}(") else text.split("\n")[0]


def _default_text(value):
    if dataclasses.is_dataclass(value) or hasattr(type(value), "__fields__"):
        return ""
    if isinstance(value, str):
        return f'"{value}"'
    if isinstance(value, list) and value and not isinstance(value[0], (int, float, str)):
        return ""
    return str(value)


def schema_rows(schema, prefix=""):
    """(dotted name, type, default, comment) of every field of ``schema``, nested sections expanded
    (Drake's own types are named, not expanded)."""
    rows = []
    instance = schema()
    comments = field_comments(schema)
    for item in dataclasses.fields(schema):
        kind = typing.get_type_hints(schema)[item.name]
        name = f"{prefix}{item.name}"
        default = getattr(instance, item.name)
        if dataclasses.is_dataclass(kind):
            rows.append((name, "section", "", comments.get(item.name, _summary(kind))))
            rows += schema_rows(kind, f"{name}.")
            continue
        element = typing.get_args(kind)[0] if typing.get_origin(kind) in (list, typing.List) else None
        if element is not None and dataclasses.is_dataclass(element):
            rows.append((f"{name}[]", f"List[{element.__name__}]", "[]", comments.get(item.name, "")))
            rows += schema_rows(element, f"{name}[].")
            continue
        rows.append((name, type_name(kind), _default_text(default), comments.get(item.name, "")))
    return rows


def schema_markdown(schema=TaskFile):
    """The Markdown page of ``docs/task_files.md``."""
    lines = ["# Task files: every field",
             "",
             "Generated from the types by `python -m drake_hybrid.scenario.schema_doc` (do not edit by hand).",
             "A task file is described in `drake_hybrid/scenario/data_task.py`; examples are in `models/tasks/`.",
             "Expressions (constraint rows, E_p rows, the start) follow the grammar of",
             "`drake_hybrid/core/expressions.py`. Drake's own types are documented by Drake:",
             ""]
    lines += [f"- `{name}`: {url}" for name, url in _DRAKE_LINKS.items()]
    lines += ["", "| field | type | default | meaning |", "|---|---|---|---|"]
    for name, kind, default, comment in schema_rows(schema):
        cell = comment.replace("|", "\\|")
        lines.append(f"| `{name}` | {kind.replace('|', 'or')} | {default.replace('|', 'or')} | {cell} |")
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    print(schema_markdown(), end="")
