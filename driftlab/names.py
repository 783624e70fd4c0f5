"""What a job's or a study's name may hold: the name a user typed is shown in tables, plots, CSV files and the
view, so it must read as it was typed. Refused: control characters (CR, LF, NUL, tabs: they break lines and
files) and the invisible format characters that reorder or hide text (bidi overrides and isolates, zero-width
characters: a name that reads differently from what it is). Shared by the REST API and the CLI."""

from __future__ import annotations

import unicodedata

MAX_NAME_LENGTH = 200


def name_problem(name: str) -> str | None:
    """Why ``name`` is refused, or None when it is fine."""
    if not name.strip():
        return "must hold a visible character"
    if len(name) > MAX_NAME_LENGTH:
        return f"must be at most {MAX_NAME_LENGTH} characters, got {len(name)}"
    for position, char in enumerate(name):
        category = unicodedata.category(char)
        if category in ("Cc", "Cf", "Cs", "Co", "Cn", "Zl", "Zp"):
            what = unicodedata.name(char, "unassigned or private")
            return (f"may not contain U+{ord(char):04X} ({what.lower()}) at position {position}: control and "
                    "invisible formatting characters are refused")
    return None
