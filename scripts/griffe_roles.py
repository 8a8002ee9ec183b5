"""Griffe extension for the API pages: Sphinx roles in docstrings become links.

voxwarp's docstrings are numpydoc with Sphinx roles (``:class:`~voxwarp.core.volume.Volume```,
``:meth:`copy```). mkdocstrings renders Markdown, where a role would show as literal text,
so this rewrites each role into an optional autorefs link: a link where the API pages
document the target, plain code where they do not (never a warning). ``~`` shows the last
name only, as in Sphinx; a name without a dot is looked up on the documented object's
class. Named in mkdocs.yml under the python handler's ``extensions``.
"""

from __future__ import annotations

import re
from typing import Any

import griffe

#: an RST code-block directive line; the indented block after it is a Markdown code block
CODE_BLOCK = re.compile(r"^[ \t]*\.\. code-block::.*\n", re.M)
ROLE = re.compile(r":(?:py:)?(class|meth|func|mod|data|attr|exc|obj|const):`(~?)([^`<>]+)`")


def _identifier(target: str, obj: griffe.Object) -> str:
    if "." in target:
        return target
    owner = obj if obj.is_class or obj.is_module else obj.parent
    return f"{owner.path}.{target}" if owner is not None else target


def rewrite(text: str, obj: griffe.Object) -> str:
    """``text`` with every Sphinx role replaced by an optional autorefs link in code, and
    without RST ``code-block`` directive lines."""

    def link(match: re.Match[str]) -> str:
        short, target = match[2] == "~", match[3].strip().rstrip("()")
        shown = target.rsplit(".", 1)[-1] if short else target
        if match[1] in ("meth", "func"):
            shown += "()"
        ident = _identifier(target, obj)
        return f'<autoref identifier="{ident}" optional><code>{shown}</code></autoref>'

    return ROLE.sub(link, CODE_BLOCK.sub("", text))


class SphinxRoles(griffe.Extension):
    """Rewrite the Sphinx roles of every docstring griffe loads."""

    def on_instance(self, *, obj: griffe.Object, **kwargs: Any) -> None:
        """Called by griffe for each module, class, function and attribute."""
        if obj.docstring is not None:
            obj.docstring.value = rewrite(obj.docstring.value, obj)
