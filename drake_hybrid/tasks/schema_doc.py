"""The task-file schema as a Markdown page, generated from the types (not written twice).

Every field of the task file (``tasks.task_file_schema.TaskFile``) and of the ``ScenarioConfig`` it
embeds, by dotted name, with its type, its default and its meaning with units: the comment written
next to the field in the source, else the field's entry (``name: text``) in its class's docstring.
Then what a task file's values mean, from the code that reads them: the expression grammar's
functions, each chart's coordinates and velocity order, each shape's sizes, the order of the arm's
joints. ``docs/task_files.md`` is this module's output::

    python -m drake_hybrid.tasks.schema_doc > docs/task_files.md

(``tests/test_task_files.py`` checks that the file is up to date.)
"""

import dataclasses
import inspect
import re
import typing

from drake_hybrid.core.expressions import CONSTANTS, FUNCTIONS, MAX_DEPTH, MAX_LENGTH
from drake_hybrid.tasks.hooks import ENTRY_POINT_GROUP, HOOK_METHODS, PACKAGE_HOOKS
from drake_hybrid.tasks.task_file import make_chart
from drake_hybrid.tasks.task_file_schema import CHARTS, SHAPES, ChartSpec, TaskFile

_FIELD_LINE = re.compile(r"^\s+(\w+)\s*:\s*[^#]*?(?:#\s*(.*))?$")
# A field's entry in its class's docstring: "name: text" (or "name, other: text"; ``name``: text), with
# continuation lines indented below it.
_DOC_FIELD = re.compile(r"^(?:``)?(\w+(?:, \w+)*)(?:``)?:(?: (.*)|)$")
# Drake's own types: documented by Drake, shown by name (and not expanded).
_DRAKE_LINKS = {
    "ModelDirective": "https://drake.mit.edu/doxygen_cxx/structdrake_1_1multibody_1_1parsing_1_1_model_directive.html",
    "Transform": "https://drake.mit.edu/doxygen_cxx/classdrake_1_1schema_1_1_transform.html",
    "MultibodyPlantConfig": "https://drake.mit.edu/doxygen_cxx/structdrake_1_1multibody_1_1_multibody_plant_config.html",
    "SimulatorConfig": "https://drake.mit.edu/doxygen_cxx/structdrake_1_1systems_1_1_simulator_config.html",
}


def field_comments(cls):
    """{field name: the comment on its line in the class's source} of a dataclass, with the comment
    lines that continue it (indented further than the field, right below it)."""
    comments = {}
    try:
        source = inspect.getsource(cls)
    except (OSError, TypeError):
        return comments
    last, last_indent = None, 0
    for line in source.splitlines():
        match = _FIELD_LINE.match(line)
        if match:
            last, last_indent = None, len(line) - len(line.lstrip())
            if match.group(2) and match.group(1) not in comments:
                comments[match.group(1)] = match.group(2).strip()
                last = match.group(1)
            continue
        continuation = re.match(r"^(\s+)#\s*(.*)$", line)
        if last and continuation and len(continuation.group(1)) > last_indent:
            comments[last] += " " + continuation.group(2).strip()
        else:
            last = None
    return comments


def docstring_fields(cls):
    """{field name: its entry in the class's docstring} ("name: text" lines and their indented
    continuations; "a, b: text" gives both a and b the text)."""
    entries, current = {}, None
    for line in inspect.cleandoc(cls.__doc__ or "").splitlines():
        match = _DOC_FIELD.match(line)
        if match:
            current = match.group(1).split(", ")
            for name in current:
                entries[name] = (match.group(2) or "").strip()
        elif current and line.strip():          # the entry goes on to the end of its paragraph
            for name in current:
                entries[name] += " " + line.strip()
        else:
            current = None
    return {name: " ".join(text.split()) for name, text in entries.items()}


def field_docs(cls):
    """{field name: its meaning}: the comment on its line in the source, else its docstring entry
    (of the class or of a base class)."""
    docs = {}
    for base in reversed(cls.__mro__):
        if dataclasses.is_dataclass(base):
            docs.update(docstring_fields(base))
            docs.update(field_comments(base))
    return docs


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
    """The first paragraph of a class's own docstring, on one line ('' for a dataclass without one)."""
    text = inspect.cleandoc(kind.__doc__ or "")
    return "" if text.startswith(f"{kind.__name__}(") else " ".join(text.split("\n\n")[0].split())


def _default_text(value):
    if dataclasses.is_dataclass(value) or hasattr(type(value), "__fields__"):
        return ""
    if isinstance(value, str):
        return f'"{value}"'
    if isinstance(value, list) and value and not isinstance(value[0], (int, float, str)):
        return ""
    return str(value)


def _union_members(kind):
    """The dataclasses of a Union of dataclasses (a YAML-tagged choice such as ``config.sensor``), else ()."""
    members = typing.get_args(kind) if typing.get_origin(kind) is typing.Union else ()
    return members if members and all(dataclasses.is_dataclass(member) for member in members) else ()


def schema_rows(schema, prefix=""):
    """(dotted name, type, default, meaning) of every field of ``schema``, nested sections expanded
    (a Union of dataclasses: each member's fields, under its YAML tag; Drake's own types are named,
    not expanded)."""
    rows = []
    instance = schema()
    docs = field_docs(schema)
    for item in dataclasses.fields(schema):
        kind = typing.get_type_hints(schema)[item.name]
        name = f"{prefix}{item.name}"
        default = getattr(instance, item.name)
        if dataclasses.is_dataclass(kind):
            rows.append((name, "section", "", docs.get(item.name, _summary(kind))))
            rows += schema_rows(kind, f"{name}.")
            continue
        members = _union_members(kind)
        if members:
            tags = ", ".join(f"!{member.__name__}" for member in members)
            rows.append((name, type_name(kind), f"!{type(default).__name__}",
                         docs.get(item.name, f"one of {tags} (YAML tag)")))
            seen = set()
            for member in members:
                for row in schema_rows(member, f"{name}."):
                    if row[0] not in seen:
                        seen.add(row[0])
                        only = [m.__name__ for m in members if row[0].split(".")[-1] in
                                {f.name for f in dataclasses.fields(m)}]
                        suffix = "" if len(only) == len(members) else f" (!{only[0]} only)"
                        rows.append((row[0], row[1], row[2], row[3] + suffix))
            continue
        element = typing.get_args(kind)[0] if typing.get_origin(kind) in (list, typing.List) else None
        if element is not None and dataclasses.is_dataclass(element):
            rows.append((f"{name}[]", f"List[{element.__name__}]", "[]", docs.get(item.name, "")))
            rows += schema_rows(element, f"{name}[].")
            continue
        rows.append((name, type_name(kind), _default_text(default), docs.get(item.name, "")))
    return rows


# What each chart's coordinates are, beyond their names (the names and their order come from the charts).
CHART_NOTES = {
    "planar": "a pose in a plane (Example 2.1): the point's coordinates (m) from `origin` along `axis_x` and "
              "`axis_y`, and theta (rad), the rotation about the plane's normal n = axis_x x axis_y from the "
              "reference orientation (R_WE = R_n(theta) R_0); velocities (axis_x . v, axis_y . v, n . w)",
    "planar_point": "a point in a plane, no orientation (x, y in m)",
    "euler_zxz": "the paper's r (2.1-2): the point (m) and z-x-z Euler angles (rad), R = Rz(phi) Rx(theta) Rz(psi); "
                 "singular where sin(theta) = 0 (`ChartSingularityError`)",
    "pose": "singularity-free: the point (m) and the nine entries of R_WE, row by row (R01 is row 0, column 1); "
            "the velocity is the world twist with the **linear velocity first** (vx, vy, vz in m/s, then wx, wy, wz "
            "in rad/s: Drake's V_WE is [w; v], the other order), so an E_p row has six entries in this order",
}

# What a shape's `size` entries are (Drake's shape constructors, in the shape's frame G at X_WG).
SHAPE_SIZES = {
    "box": "[x, y, z]: the full lengths along G's axes (m), centred at G's origin",
    "sphere": "[r]: the radius (m), centred at G's origin",
    "cylinder": "[r, length]: the radius and the full length along G's z axis (m), centred at G's origin "
                "(the flat faces at z = +-length/2)",
    "ellipsoid": "[a, b, c]: the semi-axes along G's x, y, z (m)",
    "capsule": "[r, length]: the radius and the length of the cylindrical part along G's z (m): the whole capsule "
               "is length + 2 r long",
}


def reference_sections():
    """What a task file's values mean: the expression grammar, the charts, the shapes, the joints."""
    functions = ", ".join(f"`{name}` ({arity} argument{'s' if arity > 1 else ''})"
                          for name, (_, arity) in FUNCTIONS.items())
    lines = ["## Expressions",
             "",
             "Constraint rows, E_p rows, the start's configuration and the numbers of poses outside `config` are",
             "expressions (`drake_hybrid/core/expressions.py`), parsed by a whitelisted grammar, never run as",
             "Python: numbers, the chart's coordinates (below), the file's `parameters`, "
             f"{', '.join(f'`{name}`' for name in CONSTANTS)}, `+ - * / **`, unary `-` and `+`, parentheses, and",
             f"calls of these functions only: {functions}.",
             "Angles are in radians. Anything else (attributes, subscripts, other names or calls, keywords, strings,",
             "comparisons, names starting with `_`) is refused in one line naming the file, the field and the",
             f"token; so is an expression over {MAX_LENGTH} characters or nested over {MAX_DEPTH} levels, and a",
             "constant (as the numbers written multiply out) beyond 1e300. Names are read as Python reads",
             "identifiers, NFKC-normalized (`ℌ` is `H`, the micro sign `µ` is the Greek `μ`): a parameter name",
             "must be an identifier, not a Python keyword, and not the same name as another parameter, a",
             "coordinate, a function or `pi` once normalized.",
             "",
             "## Charts: coordinates and velocity order",
             "",
             "`chart.kind` picks the chart. Its configuration coordinates are the names the constraint's rows",
             "and the start's `configuration` use, in this order; its velocity coordinates are the columns of",
             "E_p's rows (`velocity_projection.rows`, d entries each, in this order) and of E_f = dC/dx L(x).",
             "",
             "| `chart.kind` | class | configuration coordinates | velocity coordinates (E_p's columns) | what they are |",
             "|---|---|---|---|---|"]
    for kind in CHARTS:
        chart = make_chart(ChartSpec(kind=kind), "")
        coordinates = ", ".join(str(symbol) for symbol in chart.configuration_symbols)
        velocities = ", ".join(str(symbol) for symbol in chart.velocity_symbols)
        lines.append(f"| `{kind}` | `{type(chart).__name__}` | {coordinates} | {velocities} | {CHART_NOTES[kind]} |")
    lines += ["",
              "## Shapes: what `size` means",
              "",
              "`workpiece.shapes[]` are rigid hydroelastic shapes welded to the world at `X_WG` (frame G):",
              "",
              "| `shape` | Drake shape | `size` |",
              "|---|---|---|"]
    for name, (kind, count) in SHAPES.items():
        lines.append(f"| `{name}` | `{kind.__name__}` | {count} number{'s' if count > 1 else ''}: {SHAPE_SIZES[name]} |")
    lines += ["",
              "## The arm's joints",
              "",
              "`start.joint_guess`, and the columns of `q`, `v` and `torque` in a run's `log.npz`, follow the arm's",
              "joints in the plant's order of its model instance's positions (Drake's `plant.GetPositionNames(arm)`):",
              "from the base to the flange on a serial arm, one entry per joint, in rad (m for a prismatic joint).",
              "Welded joints have no entry. An arm from `robot.loader` (`tasks.robots.load_arm`) is welded to the",
              "world at `base_pose`, and every joint off the chain from its base to `flange` (gripper fingers), and",
              "every multi-dof joint on it, is **welded** at its zero position: the joints that remain are the",
              "chain's, listed base to flange in `LoadedArm.report.arm_joints` (`load_arm` prints what it welded).",
              ""]
    return lines


HOOKS_TEXT = [
    "## Hooks",
    "",
    "`hooks: [name, ...]` names Python hooks from a registry (`drake_hybrid/tasks/hooks.py`): the",
    "package's (below) and those installed packages declare in the entry point group",
    f"`{ENTRY_POINT_GROUP}` (each entry point a `TaskHook`), e.g. in their `pyproject.toml`:",
    "",
    "```toml",
    f'[project.entry-points."{ENTRY_POINT_GROUP}"]',
    'my_fixture = "my_package.hooks:MY_FIXTURE"       # a TaskHook named my_fixture',
    "```",
    "",
    "A name is a lower-case word; a `module:function` string, a dotted path or a file name is refused",
    "before any lookup, so a file can run only code that is installed and registered under a name. A",
    "hook reads the file's `parameters` it lists (all required) and supplies Task methods",
    f"({', '.join(HOOK_METHODS)}): `add_robot` instead of the `robot` section's models, `add_workpiece`",
    "after the file's workpiece, `constraint` instead of `constraint.rows`; two hooks of a file may not",
    "supply the same method. `drake-hybrid tasks` lists the known hooks. The package's:",
]

BUILT_IN_FILES_TEXT = [
    "## The built-in tasks as files",
    "",
    "Each runs as the built-in Python task: the same logs to 1e-9 and the same linearized eigenvalues",
    "(`tests/test_task_files.py`, `tests/test_task_hooks.py`). What is data and what is a hook, and why:",
    "",
    "- `window_washing.yaml`: all data.",
    "- `crank_turning.yaml` (default: true-velocity rows): the constraint (2.2-5), its branch and the",
    "  true-velocity rows are expressions, the crank a model directive welded at a pose given by the",
    "  parameters. Hooks: `ur5e_with_pad` (below) and `crank`: Drake's model directives have no",
    "  constraint directive, so the SAP weld constraint that holds the pad on the handle is Python; the",
    "  start is inverse kinematics to the handle's pose (no search for a pressing depth: the weld holds",
    "  the pad), the crank's joint state at the start, its inertia along the velocity rows",
    "  (`mechanism.source: plant`), the handle-inertia eigenvalue shifts and the run note compute with",
    "  the plant. The paper's (3.3-6) rows (`--option velocity_rows=paper`): the same file with the",
    "  rows `-(y - crank_center_y), x - crank_center_x, 0, 1, 0, 0` and the hook `crank_paper_rows`,",
    "  whose source turns the true-velocity command into the paper's pseudo-velocity (3.3-8).",
    "- `sphere_polishing.yaml` (default: latitude path, pose chart, true-velocity rows): the rows are",
    "  expressions of the pose chart's coordinates. Hooks: `sphere_paper_constraint`: the equator fix",
    "  of (2.2-8) drops, at each evaluation, the component of P x a with the largest |a_k|: three sets",
    "  of rows switched at run time, which one list of rows cannot say; `ur5e_with_pad`: the UR5e comes",
    "  from airo-models, which ships no package.xml (no `package://` URL reaches it), and the built-in",
    "  task drops its links' collision geometries. The start is a pose (six numbers) on the path. The",
    "  other variants (`path: pole`, `chart: euler`, `velocity_rows: paper`) are not written as files:",
    "  the first two are the same file with other rows and start; the paper's (3.3-11) rows need a",
    "  pseudo-velocity source hook for the sphere, which the package does not have.",
    "- `grinding.yaml` (default: the window with a rough patch, impedance/force): hook `rough_patch`:",
    "  the patch's own friction coefficient follows from `config.contact.friction` (Drake combines",
    "  2 mu1 mu2 / (mu1 + mu2); the pad must see `rough_friction` on it), and the run notes say where",
    "  the pad ends relative to the patch. The sphere variant (`workpiece: sphere`) is",
    "  `sphere_polishing.yaml` with the grinding gains, mode and friction; not written as a file.",
    "",
    "Task files have no task options (`--option`): a variant is another file.",
    "",
    "## URLs and expressions in poses",
    "",
    "`robot.loader.path` and the directives' `add_model.file` take `package://<name>/...` URLs: the",
    "package `drake_hybrid` (models/), the model packages pip installed in the cmeel layout",
    "(`<site-packages>/cmeel.prefix/share/<name>/package.xml`, e.g. `example-robot-data`) and the file's",
    "`packages: {name: folder}` (folders relative to the file); also `file://` URLs and paths (relative",
    "to the file). The number lists of poses outside `config` (`translation: [...]`, `rotation: !Rpy",
    "{deg: [...]}`: the directives' `X_PC`/`X_PF`, the shapes' `X_WG`, the tool's and the loader's poses)",
    "take expressions of the parameters, e.g. `X_PC: {translation: [crank_center_x, crank_center_y,",
    "crank_height]}`. A file shipped to Dask workers travels by its text: the files it names must be at",
    "the same paths (or in the same packages) there.",
]


def schema_markdown(schema=TaskFile):
    """The Markdown page of ``docs/task_files.md``."""
    lines = ["# Task files: every field",
             "",
             "Generated from the types by `python -m drake_hybrid.tasks.schema_doc` (do not edit by hand).",
             "A task file is described in `drake_hybrid/tasks/task_file_schema.py`; examples are in `models/tasks/`.",
             "Expressions (constraint rows, E_p rows, the start) follow the grammar of",
             "`drake_hybrid/core/expressions.py`. Drake's own types are documented by Drake:",
             ""]
    lines += [f"- `{name}`: {url}" for name, url in _DRAKE_LINKS.items()]
    lines += ["", "| field | type | default | meaning |", "|---|---|---|---|"]
    for name, kind, default, comment in schema_rows(schema):
        cell = comment.replace("|", "\\|")
        lines.append(f"| `{name}` | {kind.replace('|', 'or')} | {default.replace('|', 'or')} | {cell} |")
    lines += ["", *reference_sections(), *HOOKS_TEXT, "", "| hook | provides | parameters it reads | plant | what |", "|---|---|---|---|---|"]
    for hook in PACKAGE_HOOKS:
        lines.append(f"| `{hook.name}` | {', '.join(hook.provides)} | {', '.join(hook.parameters) or '-'} | "
                     f"{'any' if hook.continuous_plant else 'discrete'} | {hook.description} |")
    lines += ["", *BUILT_IN_FILES_TEXT]
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    print(schema_markdown(), end="")
