"""Outside strings made inert where the benchmark renders them (docs/reliability.md, "Submissions
you can trust").

An agent's name and group, a note, a command: anything a scorecard carries came from whoever
played it. Wherever the benchmark writes such a string into a page (``leaderboard.md``,
``scorecard.md``), a figure's labels or a line of the terminal, it goes through one of these
functions first, so it is read as the text it is and never as structure: no line break (a new
table row, a heading), no table cell separator, no HTML, link, image, emphasis or code span of
its own, no terminal control sequence.
"""

from __future__ import annotations

import re
import unicodedata

# every character Markdown (CommonMark with GitHub's tables, strikethrough and math) gives a
# meaning inside a line: each is written with a backslash, which CommonMark reads as the literal
# character ("_" only where it could open or close emphasis: not between two letters or digits,
# so greedy_r stays as it is)
_MARKDOWN = set("\\`*[]<>|&~$!_")


def one_line(text) -> str:
    """``text`` as one line of plain characters: every control, format (zero-width, direction
    override) and line or paragraph separator character a space, runs of spaces one."""
    chars = (" " if unicodedata.category(c) in ("Cc", "Cf", "Zl", "Zp") else c for c in str(text))
    return " ".join("".join(chars).split())


def md_text(text) -> str:
    """``text`` as inert Markdown inline text (a table cell, a heading's words): one line, every
    character with a meaning in a line escaped."""
    s = one_line(text)
    out = []
    for k, c in enumerate(s):
        if c == "_" and 0 < k < len(s) - 1 and s[k - 1].isalnum() and s[k + 1].isalnum():
            out.append(c)  # inside a word: never emphasis
        elif c in _MARKDOWN:
            out.append("\\" + c)
        else:
            out.append(c)
    return "".join(out)


def md_code(text) -> str:
    """``text`` as an inert Markdown code span: one line, fenced by more backticks than it holds
    in a row (its content is then shown as it is: no HTML, no link)."""
    s = one_line(text)
    fence = "`" * (1 + max((len(run) for run in re.findall(r"`+", s)), default=0))
    pad = " " if s.startswith("`") or s.endswith("`") else ""
    return f"{fence}{pad}{s}{pad}{fence}"


def plot_label(text, longest: int | None = None, keep: int | None = None, more: str = "...") -> str:
    """``text`` as a matplotlib label: one line (longer than ``longest`` characters: its first
    ``keep`` and ``more``), ``$`` escaped (no mathtext)."""
    s = one_line(text)
    if longest is not None and len(s) > longest:
        s = s[:keep] + more
    return s.replace("$", r"\$")


__all__ = ["md_code", "md_text", "one_line", "plot_label"]
