"""The documentation's inline quotes of an output, for the tests that produce that output.

A page quotes a line a command prints (```` `run  INCOMPLETE: the last 9.406 s
...` ````) whose figures depend on the run. The test that runs the command
checks the line it printed has the form quoted: the quote's numbers stand for
any numbers, its ``...`` for any text, and spaces for any run of spaces.
"""

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
_NUMBER = r"[+\-−]?\d+(?:\.\d+)?"


def _flat(text):
    return " ".join(text.split())


def inline_quote(doc, start):
    """The inline-code span of ``doc`` (a path from the root) that begins with ``start``."""
    text = _flat((ROOT / doc).read_text(encoding="utf-8"))
    spans = [s for s in re.findall(r"`([^`]+)`", text) if s.startswith(_flat(start))]
    assert len(spans) == 1, (doc, start, spans)
    return spans[0]


def quoted_form(doc, start):
    """A pattern of the quote of ``doc`` beginning with ``start``: its form, any figures."""
    return form_of(inline_quote(doc, start))


def form_of(quote):
    """A pattern of a quoted output: its words, any figures (dates too) where it has figures."""
    out = []
    for part in re.split(rf"(\.\.\.|{_NUMBER})", quote):
        if part == "...":
            out.append(".*?")
        elif re.fullmatch(_NUMBER, part):
            out.append(_NUMBER)
        else:
            out.append(r"\s+".join(re.escape(word) for word in part.split(" ")))
    return re.compile("".join(out))
