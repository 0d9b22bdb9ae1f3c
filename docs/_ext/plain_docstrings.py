"""Sphinx extension: the project's plain-text docstrings as reStructuredText.

The package's docstrings are written to be read in the source and in ``help()``: reST for literals,
tables and directives, but also two plain-text habits that reST reads otherwise:

* ``|x|`` for a norm or an absolute value, which reST takes for a substitution reference (escaped;
  in a simple table's cells, where a backslash would shift the columns, written as U+2223);
* fields as ``name: what it is`` with indented continuation lines (a dataclass's fields, a function's
  arguments), and indented continuations after a paragraph, which reST reads as unexpected
  indentation.

This extension (``autodoc-process-docstring``) turns a run of such field lines into a definition
list (the name as the term), separates a change of indentation by a blank line, and escapes a bar
outside inline literals. Literal blocks (after ``::``), directives (``.. name::``), simple tables
(``===`` borders), grid tables and bullet lists are left as written. ``plain_to_rst`` is a pure
function of the lines (tested in ``tests/test_docs.py``).
"""

import re

_FIELD = re.compile(r"^(\s*)([A-Za-z_][\w.\[\]]*(?:, [A-Za-z_][\w.\[\]]*)*|``[^`]+``(?:, ``[^`]+``)*): (\S.*)$")
_BORDER = re.compile(r"^\s*=+( +=+)+\s*$")
_BULLET = re.compile(r"^(\s*)([-*+]|\d+\.|#\.) ")
_DIRECTIVE = re.compile(r"^\s*\.\. ")
_INLINE_LITERAL = re.compile(r"(``.+?``)")


def _indent(line):
    return len(line) - len(line.lstrip())


def _escape_bars(line):
    """Escape ``|`` outside ````literal```` spans."""
    parts = _INLINE_LITERAL.split(line)
    return "".join(part if index % 2 else re.sub(r"(?<!\\)\|", r"\\|", part) for index, part in enumerate(parts))


def _field_runs(lines):
    """Indices of field lines to turn into definition-list items: a run of consecutive non-blank lines
    made of field lines at one indentation and their more-indented continuations, with at least one
    continuation or two fields."""
    chosen = set()
    index = 0
    while index < len(lines):
        match = _FIELD.match(lines[index])
        if not match:
            index += 1
            continue
        base, fields, continuations, end = len(match.group(1)), [index], 0, index + 1
        while end < len(lines) and lines[end].strip():
            if _indent(lines[end]) > base:
                continuations += 1
            elif _indent(lines[end]) == base and _FIELD.match(lines[end]):
                fields.append(end)
            else:
                break
            end += 1
        starts_run = index == 0 or not lines[index - 1].strip() or _indent(lines[index - 1]) != base
        if starts_run and end - index > 1 and (continuations or len(fields) > 1) and (
                end == len(lines) or not lines[end].strip() or _indent(lines[end]) < base):
            chosen.update(fields)
        index = end
    return chosen


def plain_to_rst(lines):
    """The docstring's lines as reST that docutils reads without a warning (see the module docstring)."""
    fields = _field_runs(lines)
    out = []
    verbatim = None        # indentation of the line that opened a literal block or a directive
    in_table = False
    previous = None        # (the last line emitted outside verbatim blocks, the lines of its paragraph)
    field_shift = None     # (base indentation, shift) of a field's continuation lines, re-indented under its term
    for index, line in enumerate(lines):
        stripped = line.strip()
        indent = _indent(line)
        if field_shift is not None and stripped:
            if indent > field_shift[0] and verbatim is None:
                line = " " * (indent + field_shift[1]) + line.lstrip()
                indent = _indent(line)
            elif indent <= field_shift[0]:
                field_shift = None
        if verbatim is not None:
            if not stripped or indent > verbatim:
                out.append(line)
                continue
            verbatim = None
            if out and out[-1].strip():
                out.append("")
        if in_table:
            # a bar inside a cell would be a substitution; a backslash would shift the columns, so it
            # becomes a bar of the same width that reST does not read (U+2223)
            out.append(line if _BORDER.match(line) else line.replace("|", "\u2223"))
            if _BORDER.match(line) and (index + 1 == len(lines) or not lines[index + 1].strip()):
                in_table = False
            previous = None
            continue
        if not stripped:
            out.append(line)
            previous = None
            continue
        if stripped.startswith(("+-", "+=")):       # a grid table: as written, up to the blank line after it
            verbatim = indent - 1
            out.append(line)
            continue
        if _BORDER.match(line):
            if out and out[-1].strip():
                out.append("")
            out.append(line)
            in_table = True
            continue
        if previous is not None:
            prev_line, prev_lines_in_paragraph = previous
            prev_indent = _indent(prev_line)
            bullet = _BULLET.match(prev_line)
            continues_bullet = bullet and indent == len(bullet.group(0))
            new_bullet = _BULLET.match(line) and previous_bullet_indent(out) == indent
            bullet_above = previous_bullet_indent(out)
            if indent < prev_indent and not new_bullet and index not in fields:
                out.append("")
            elif bullet_above is not None and not _BULLET.match(line) and indent <= bullet_above:
                out.append("")                 # a paragraph after a list
            elif indent > prev_indent and not continues_bullet and not prev_line.rstrip().endswith("::") and (
                    prev_lines_in_paragraph > 1):
                out.append("")
        if index in fields:
            match = _FIELD.match(line)
            out.append(f"{match.group(1)}{match.group(2)}")
            text = f"{match.group(1)}    {match.group(3)}"
            out.append(_escape_bars(text))
            previous = (text, 1)
            following = lines[index + 1] if index + 1 < len(lines) else ""
            if following.strip() and _indent(following) > len(match.group(1)):
                field_shift = (len(match.group(1)), len(match.group(1)) + 4 - _indent(following))
            continue
        out.append(_escape_bars(line))
        if _DIRECTIVE.match(line) or stripped.endswith("::"):
            verbatim = indent
        count = 1 if previous is None or _indent(previous[0]) != indent else previous[1] + 1
        previous = (line, count)
    return out


def previous_bullet_indent(out):
    """The indentation of the nearest bullet above in the same block (None if there is none)."""
    for line in reversed(out):
        if not line.strip():
            return None
        bullet = _BULLET.match(line)
        if bullet:
            return len(bullet.group(1))
    return None


def _process(app, what, name, obj, options, lines):
    lines[:] = plain_to_rst(lines)


def setup(app):
    app.connect("autodoc-process-docstring", _process)
    return {"version": "1", "parallel_read_safe": True, "parallel_write_safe": True}
