"""Plain-text help for the command lines: module docstrings are written in RST, ``--help`` is read in a terminal."""
from __future__ import annotations

import re

# :role:`text`, :domain:role:`text`, with an optional leading ~ (show the last dotted part only)
_ROLE = re.compile(r":(?:[A-Za-z][\w+-]*:)+`([^`]+)`")
_LITERAL = re.compile(r"``(.+?)``")
_DEFAULT_ROLE = re.compile(r"(?<![\w`])`([^`]+)`(?![\w`])")
_TITLE_TARGET = re.compile(r"^(.*?)\s*<[^<>]+>$")


def _role_text(match: re.Match[str]) -> str:
    """What a role shows: ``title`` of ``title <target>``, the last part of ``~a.b.c``, else the text itself."""
    text = match.group(1).strip()
    titled = _TITLE_TARGET.match(text)
    if titled and titled.group(1):
        return titled.group(1)
    if text.startswith("~"):
        return text[1:].rsplit(".", 1)[-1]
    return text.lstrip("!")


def plain_text(text: str) -> str:
    """``text`` without RST inline markup: ````literal```` -> literal, ``:role:`target``` -> target.

    Args:
        text: RST text, e.g. a module docstring.

    Returns:
        The same text with double backticks and roles (``:func:``, ``:class:``, ``:py:meth:`` ...) removed; a
        role written ``title <target>`` shows its title, ``~pkg.mod.name`` its last part (as Sphinx renders them).
    """
    text = _ROLE.sub(_role_text, text)
    text = _LITERAL.sub(r"\1", text)
    return _DEFAULT_ROLE.sub(r"\1", text)


def description(doc: str | None) -> str:
    """The first line of a module docstring as plain text: the ``description`` of an argument parser.

    Args:
        doc: the module's ``__doc__`` (None under ``python -OO``, which strips docstrings).

    Returns:
        The first line without RST markup, or "" without a docstring.
    """
    if not doc:
        return ""
    return plain_text(doc.strip().splitlines()[0]).strip()


__all__ = ["description", "plain_text"]
