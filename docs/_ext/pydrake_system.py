"""Sphinx extension: Drake's ``.. pydrake_system::`` port blocks drawn as port diagrams.

Drake documents every system with a YAML block of its name and ports (C++ ``@system`` ...
``@endsystem``, Python ``.. pydrake_system::``) and renders it as a box with the input ports on its
left and the output ports on its right. Drake's own extension (``doc/pydrake/pydrake_sphinx_extension.py``
with ``doc/doxygen_cxx/system_doxygen.py``) is not shipped in the ``drake`` wheel; this is the same
drawing, written for this project:

* ``pydrake_system`` directive: the YAML (``name``, ``input_ports``, ``output_ports``; a port may
  carry a note in parentheses, ``contact_phase (only with guarded_move)``) becomes a table in HTML
  (the port names on either side of the system's box, the notes in small type) and a literal block
  in every other builder. A block that is not such YAML is an error naming what is wrong.
* Private base classes (``_BaselineMixin``) are left out of a class's bases, as Drake's extension
  leaves out pybind11's.
* Systems made with Drake's ``TemplateSystem`` are documented under their public name: the module's
  ``HybridController = HybridController_[None]`` is a class whose ``__name__`` is the instantiation's
  (``HybridController_[float]``), which autodoc would show as an alias. The extension gives the
  default instantiations their public names and their constructor's signature (``_construct``'s,
  not the template's ``*args, **kwargs``) in the documentation build only, and appends to each
  one's docstring the instantiations its template offers (``HybridController_[float]``,
  ``HybridController_[AutoDiffXd]``).
"""

import html
import importlib
import inspect
import pkgutil
import re

import yaml
from docutils import nodes
from docutils.parsers.rst import Directive
from pydrake.common.cpp_template import TemplateBase

_PORT_NOTE = re.compile(r"^\s*([^()]+?)\s*(?:\((.*)\))?\s*$")


def parse_system_yaml(text):
    """(name, [(input port, note)], [(output port, note)]) of a pydrake_system block; ValueError on a
    block that is not its YAML."""
    try:
        block = yaml.safe_load(text)
    except yaml.YAMLError as error:
        raise ValueError(f"not YAML: {error}") from None
    if not isinstance(block, dict) or not isinstance(block.get("name"), str):
        raise ValueError("needs a 'name:' (the system's name)")
    unknown = set(block) - {"name", "input_ports", "output_ports"}
    if unknown:
        raise ValueError(f"unknown keys {sorted(unknown)}; allowed: name, input_ports, output_ports")

    def ports(key):
        entries = block.get(key) or []
        if not isinstance(entries, list) or not all(isinstance(entry, str) for entry in entries):
            raise ValueError(f"'{key}' must be a list of port names")
        return [_PORT_NOTE.match(entry).groups(default="") for entry in entries]

    return block["name"], ports("input_ports"), ports("output_ports")


def _port_rows(ports, side):
    cells = []
    for name, note in ports:
        note_html = f' <span class="pydrake-system-note">({html.escape(note)})</span>' if note else ""
        if side == "input":
            cells.append(f'<tr><td class="pydrake-system-input">{html.escape(name)}{note_html} &rarr;</td></tr>')
        else:
            cells.append(f'<tr><td class="pydrake-system-output">&rarr; {html.escape(name)}{note_html}</td></tr>')
    return "".join(cells)


def system_html(name, inputs, outputs):
    """The port diagram: input ports, the system's box, output ports (the layout of Drake's
    ``system_yaml_to_html``)."""
    return ('<table class="pydrake-system"><tr>'
            f'<td class="pydrake-system-ports"><table>{_port_rows(inputs, "input")}</table></td>'
            f'<td class="pydrake-system-box">{html.escape(name)}</td>'
            f'<td class="pydrake-system-ports"><table>{_port_rows(outputs, "output")}</table></td>'
            '</tr></table>')


def system_text(name, inputs, outputs):
    """The same diagram in plain text (builders other than HTML)."""
    lines = [f"{name}"]
    lines += [f"  input  {port}" + (f" ({note})" if note else "") for port, note in inputs]
    lines += [f"  output {port}" + (f" ({note})" if note else "") for port, note in outputs]
    return "\n".join(lines)


class PydrakeSystemDirective(Directive):
    """``.. pydrake_system::`` with its YAML as content."""

    has_content = True

    def run(self):
        try:
            name, inputs, outputs = parse_system_yaml("\n".join(self.content))
        except ValueError as error:
            raise self.error(f"pydrake_system: {error}")
        if self.state.document.settings.env.app.builder.format == "html":
            return [nodes.raw("", system_html(name, inputs, outputs), format="html")]
        return [nodes.literal_block(text=system_text(name, inputs, outputs))]


def template_systems(package_name):
    """(module, public name, TemplateSystem) of every ``Name = Name_[None]`` in the package."""
    package = importlib.import_module(package_name)
    found = []
    for info in pkgutil.walk_packages(package.__path__, f"{package_name}."):
        module = importlib.import_module(info.name)
        for name, value in vars(module).items():
            template = getattr(module, f"{name}_", None)
            if inspect.isclass(value) and isinstance(template, TemplateBase) and value is template[None]:
                found.append((module, name, template))
    return found


def name_template_systems(app, config):
    """Give each default instantiation its public name (documentation build only) and list the
    template's instantiations at the end of its docstring."""
    for module, name, template in template_systems(config.pydrake_system_package):
        cls = getattr(module, name)
        cls.__name__ = cls.__qualname__ = name
        construct = inspect.signature(cls._construct)     # the constructor's real arguments
        cls.__signature__ = construct.replace(parameters=[parameter for key, parameter in construct.parameters.items()
                                                          if key not in ("self", "converter")])
        names = ", ".join(f"``{template._instantiation_name(param)}``" for param in template.param_list)
        cls.__doc__ = (inspect.cleandoc(cls.__doc__ or "")
                       + f"\n\n``{name}`` is ``{name}_[None]``; the template ``{name}_`` has the instantiations "
                       + f"{names} (Drake's scalar conversion: ``ToAutoDiffXd()``).\n")


# Drake's TemplateSystem also binds each instantiation in its module under a mangled name
# (``HybridController_𝓣float𝓤``): the same class as the public name, not a name to document twice.
MANGLED_INSTANTIATION = "\U0001d4e3"      # the mangling's opening character


def skip_mangled_instantiations(app, what, name, obj, skip, options):
    return True if MANGLED_INSTANTIATION in name else None


def public_bases(app, name, obj, options, bases):
    """Show only public base classes (a private mixin such as ``_BaselineMixin`` is an implementation
    detail with no page of its own)."""
    bases[:] = [base for base in bases if not getattr(base, "__name__", "").startswith("_")]


def setup(app):
    app.add_directive("pydrake_system", PydrakeSystemDirective)
    app.connect("autodoc-process-bases", public_bases)
    app.connect("autodoc-skip-member", skip_mangled_instantiations)
    app.add_config_value("pydrake_system_package", "", "env")
    app.connect("config-inited", name_template_systems)
    app.add_css_file("pydrake_system.css")
    return {"version": "1", "parallel_read_safe": True, "parallel_write_safe": True}
