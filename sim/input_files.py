"""Reading a JSON input file (an objects file, a task file, a run's run.json and config.json) without trusting it.

One reader for all of them, so each is bounded the same way:
- a regular file only, opened without blocking: `/dev/zero` would be read for ever, a FIFO would wait for a writer;
- at most `max_bytes` read (one byte more tells a larger file), then UTF-8;
- nesting at most `max_nesting` deep, counted before the parser recurses (Python's json recurses once a level: a
  100,000-deep file would end in a RecursionError);
- integer literals of at most MAX_DIGITS digits (a 5,000-digit integer costs quadratic time to convert);
- strict JSON: a key repeated in one object is refused (json.loads keeps the last value silently: `"mass_g": 420,
  "mass_g": 14` would run at 14 g), and so are NaN and Infinity where `strict` (not JSON; an objects file reports
  them itself, naming the field).

`InputFileError` is one line (a ValueError); it names what was read (`what`: "the objects file", a path) and, for a
repeated key, the key. The caller prefixes the path where its message does not say it.
"""

from __future__ import annotations

import json
import os
import re
import stat

MAX_NESTING = 32        # the deepest schema read here nests 5 deep; deeper input would only exhaust the parser
MAX_DIGITS = 32         # a float64 has 17 significant digits; 32 leaves room for any integer a file here holds
MAX_SHOWN = 60          # characters of a refused value or key quoted in an error line (CONTRACTS.md)


class InputFileError(ValueError):
    """An input file that is not read: one line saying why. A character that does not print (a newline, an ANSI
    escape in a path or a key) appears as its Python escape, so the line cannot move or recolour a terminal.
    From read_bytes, `reason` says which refusal it is ("kind", "size", "os") and `detail` its particulars (the
    kind of file, or the system's reason), for a caller that words its own line."""

    def __init__(self, message: str, reason: str | None = None, detail: str | None = None):
        super().__init__(printable(str(message)))
        self.reason, self.detail = reason, detail


def kind_of(mode: int) -> str:
    """What a file that is not a regular file is, from its st_mode: 'a directory', 'a FIFO (named pipe)', ..."""
    return ("a directory" if stat.S_ISDIR(mode) else "a FIFO (named pipe)" if stat.S_ISFIFO(mode) else
            "a device" if stat.S_ISCHR(mode) or stat.S_ISBLK(mode) else "a socket" if stat.S_ISSOCK(mode) else
            "no regular file")


def printable(text: str) -> str:
    """Every character that does not print (a newline, an ANSI escape, a bidi control) as its Python escape: a line
    that quotes it stays one line and cannot move or recolour a terminal."""
    return "".join(c if c.isprintable() else repr(c)[1:-1] for c in text)


def show(value) -> str:
    """A refused value as an error line quotes it, the project's one quoter of input values (objects files, task
    files, sweep files): JSON (so a string is quoted and every non-ASCII or control character escaped), cut to
    MAX_SHOWN characters."""
    try:
        text = json.dumps(value, ensure_ascii=True)
    except (TypeError, ValueError, RecursionError):   # not a JSON value (a Python object, a TOML date)
        text = printable(repr(value))
    return text if len(text) <= MAX_SHOWN else text[:MAX_SHOWN - 3] + "..."


def quoted(word) -> str:
    """A key or a word as an error line quotes it: in single quotes, escaped as `show` escapes a string."""
    text = json.dumps(str(word), ensure_ascii=True)[1:-1].replace('\\"', '"')
    return "'" + (text if len(text) <= MAX_SHOWN else text[:MAX_SHOWN - 3] + "...") + "'"


# a string (an unterminated one runs to the end of the text) or a bracket; the unrolled loop never backtracks, so
# one pass is linear in the text however its quotes and backslashes fall
_TOKEN = re.compile(r'"[^"\\]*(?:\\.[^"\\]*)*"?|[\[\]{}]', re.DOTALL)


def nesting(text: str) -> int:
    """The deepest nesting of [ and { outside strings (the text is not yet known to be valid JSON). Linear time."""
    depth = deepest = 0
    for m in _TOKEN.finditer(text):
        c = m.group()
        if c in "[{":
            depth += 1
            if depth > deepest:
                deepest = depth
        elif c in "]}":
            depth -= 1
    return deepest


def read_bytes(path, what: str, max_bytes: int) -> bytes:
    """The bytes of a regular file of at most max_bytes, read without blocking on a FIFO or a device and no further
    than the limit (/dev/zero never ends). The one bounded reader of input files (the sweeps' read_bounded words
    its refusals from `reason` and `detail`)."""
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0))
        with os.fdopen(fd, "rb") as f:
            mode = os.fstat(f.fileno()).st_mode
            if not stat.S_ISREG(mode):
                raise InputFileError(f"{what} is {kind_of(mode)}, not a regular file", "kind", kind_of(mode))
            raw = f.read(max_bytes + 1)
    except OSError as e:
        raise InputFileError(f"cannot read {what}: {type(e).__name__}: {e}", "os", str(e.strerror or e)) from None
    if len(raw) > max_bytes:
        raise InputFileError(f"{what} is larger than {max_bytes:,} bytes", "size", f"{max_bytes:,} bytes")
    return raw


def read_json(path, what: str, max_bytes: int = 1_000_000, max_nesting: int = MAX_NESTING, strict: bool = True):
    """The decoded JSON of a bounded, strict input file (the module's docstring); InputFileError otherwise."""
    raw = read_bytes(path, what, max_bytes)
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as e:
        raise InputFileError(f"cannot read {what}: not UTF-8 text (byte {e.start})") from None
    return loads(text, what, max_nesting, strict)


def loads(text: str, what: str, max_nesting: int = MAX_NESTING, strict: bool = True):
    """JSON text decoded as `read_json` decodes a file's."""
    depth = nesting(text)
    if depth > max_nesting:
        raise InputFileError(f"{what} nests {depth} levels deep (at most {max_nesting})")
    try:
        return json.loads(text, parse_int=_bounded_int, object_pairs_hook=_unique_keys,
                          **({"parse_constant": _no_constant} if strict else {}))
    except json.JSONDecodeError as e:
        raise InputFileError(f"malformed JSON at line {e.lineno} column {e.colno}: {e.msg}") from None
    except _Refused as e:
        raise InputFileError(f"{what}: {e}") from None
    except RecursionError:   # not reached under max_nesting; a caller's larger bound must not make a traceback
        raise InputFileError(f"{what} nests too deeply (at most {max_nesting} levels)") from None


class _Refused(ValueError):
    pass


def _unique_keys(pairs: list) -> dict:
    out = {}
    for k, v in pairs:
        if k in out:
            raise _Refused(f"the key {quoted(k)} appears twice in one object (JSON would keep the last value "
                           "silently): remove one")
        out[k] = v
    return out


def _no_constant(word: str):
    raise _Refused(f"{word} is not a JSON value (use a finite number)")


def _bounded_int(literal: str) -> int:
    if len(literal.lstrip("-")) > MAX_DIGITS:
        raise _Refused(f"an integer of {len(literal.lstrip('-'))} digits (at most {MAX_DIGITS}): {literal[:12]}...")
    return int(literal)
