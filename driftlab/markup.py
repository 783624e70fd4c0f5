"""Text a user typed (job and study names) or the service wrote (error messages), made safe to put into
markdown: the view's (viser renders markdown with raw HTML enabled, so a name would be stored XSS) and the
reports' report.md. Every such string passes through :func:`plain` (OWASP's contextual output encoding: HTML
first, then markdown's own syntax)."""

from __future__ import annotations

import html
import re
import unicodedata

# Markdown's ASCII punctuation that starts emphasis, code, links, images, headings, lists, tables or
# strikethrough; '<' and '&' are HTML-encoded before (a backslash does not stop raw HTML in every renderer).
_MARKDOWN_PUNCTUATION = re.compile(r"([\\`*_{}\[\]()#+\-.!|~$])")


def _visible(text: str) -> str:
    """Control characters as spaces (a name's CR/LF would start a new markdown block), and format characters
    (bidi overrides, zero-width joiners) dropped: the name reads left to right as typed."""
    out = []
    for char in text:
        category = unicodedata.category(char)
        if category == "Cc":
            out.append(" ")
        elif category != "Cf":
            out.append(char)
    return "".join(out)


def plain(value: object) -> str:
    """``value`` as markdown text that renders exactly as its characters read: no tag, link, image or emphasis."""
    text = html.escape(_visible(str(value)), quote=False)
    return _MARKDOWN_PUNCTUATION.sub(r"\\\1", text)
