"""Griffe extension for the docs build: the docstrings use reST roles (``:class:`X```,
``:meth:`~a.B.c```) that Markdown would show verbatim; they become inline code."""

from __future__ import annotations

import re
from typing import Any

import griffe

_ROLE = re.compile(r":(?:class|meth|func|attr|mod|data|exc|obj):`~?([^`]+)`")
_LITERAL = re.compile(r"(\S)::$", re.M)  # reST "text::" before an indented block


class SphinxRoles(griffe.Extension):
    """Rewrite reST roles to Markdown inline code in every docstring."""

    def on_instance(self, *, obj: griffe.Object, **kwargs: Any) -> None:
        if obj.docstring is not None:
            obj.docstring.value = _LITERAL.sub(r"\1:", _ROLE.sub(r"`\1`", obj.docstring.value))
