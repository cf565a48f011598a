"""Product text: the docstrings and comments of `jaxrod/` and `design/` carry equations,
conventions and design decisions, not measurements of one machine on one day. Timings live
in `benchmarks/results/` (docs/benchmarks.md), the model's conventions in docs/model.md.

Read from the source (`ast` for the docstrings of modules, classes, functions and attributes,
`tokenize` for the comments); nothing is imported or compiled. A hit fails with its file and
line.
"""

import ast
import io
import pathlib
import re
import threading
import tokenize

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]

_TIME = r"\d+(?:\.\d+)?\s?(?:s|ms|us|µs)\b(?![\^_'])"
_CLAUSE = r"(?:(?!\.\s)[^;]){0,60}?"  # within one clause: no sentence end, no semicolon
PATTERNS = {
    "a date": re.compile(r"\b(?:19|20)\d\d-(?:0[1-9]|1[0-2])(?:-(?:0[1-9]|[12]\d|3[01]))?\b"),
    # a wall time compared with another or summed up ("0.056 s vs 0.089 s", "116 ms -> 85 ms",
    # "0.2 s per gap ... instead of 3 ms", "93.1 s in all", "72 ms with, 76 ms without"), or a
    # cost quoted as a time ("~20 s compiling", "0.1 s to compile", "31 us per member",
    # "~0.3 s at n = 100")
    "a measured wall time": re.compile(
        _TIME + r"(?:" + _CLAUSE + r"(?:\b(?:vs|against|instead of)\b|" + _TIME + r")|\s*->|\s+in all\b"
        r"|\s+(?:with|without|alone|compiling|computing|to compile|of dispatch)\b"
        r"|\s+per (?:call|member|scene|gap|solve|run)\b|\s+at [Nn] =)"
        r"|\b(?:vs|against|instead of)\s+" + _TIME),
    "a measured speed-up": re.compile(r"\b\d+(?:\.\d+)?x (?:faster|slower|longer|quicker|less time|more time)\b"
                                      r"|\b\d+(?:\.\d+)? ?% (?:more|less) time\b"),
    "a machine": re.compile(r"\b(?:\d+|two|four)(?:[ -]CPU)?[ -]cores?\b|\bon this machine\b", re.IGNORECASE),
    "history": re.compile(r"\bthis session\b|\b(?:at|since|until|before|after) stop \d+\b", re.IGNORECASE),
    "MODEL.md (the model's page is docs/model.md)": re.compile(r"MODEL\.md"),
}


_MATH = re.compile(r"\$\$.*?\$\$|\$[^$]*\$")


def offences(text):
    """The names of the `PATTERNS` that `text` matches: line breaks and indents read as one
    space, TeX math (`$...$`, `$$...$$`) left out."""
    flat = _MATH.sub(" ", " ".join(text.split()))
    return [name for name, pattern in PATTERNS.items() if pattern.search(flat)]


from helpers import parse_source as _parse  # noqa: E402


def _sources():
    for folder in ("jaxrod", "design"):
        yield from sorted((ROOT / folder).rglob("*.py"))


def _is_text(node):
    return isinstance(node, ast.Expr) and isinstance(node.value, ast.Constant) and isinstance(node.value.value, str)


def _texts(path):
    """(line, kind, text) of every docstring (of a module, class or function, and of an
    attribute: a string right after an assignment, which the API pages render too) and every
    comment of the file."""
    source = path.read_text()
    for node in ast.walk(_parse(source)):
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)):
            doc = ast.get_docstring(node, clean=False)
            if doc:
                yield node.body[0].lineno, "docstring", doc
        if isinstance(node, (ast.Module, ast.ClassDef)):
            for before, after in zip(node.body, node.body[1:]):
                if isinstance(before, (ast.Assign, ast.AnnAssign)) and _is_text(after):
                    yield after.lineno, "docstring", after.value.value
    # a comment wrapped over several lines is read as one text, from its first line
    block, start, last = [], None, None
    for tok in tokenize.generate_tokens(io.StringIO(source).readline):
        if tok.type == tokenize.COMMENT:
            if last is not None and tok.start[0] == last + 1:
                block.append(tok.string.lstrip("#"))
            else:
                if block:
                    yield start, "comment", " ".join(block)
                block, start = [tok.string.lstrip("#")], tok.start[0]
            last = tok.start[0]
    if block:
        yield start, "comment", " ".join(block)


def test_docstrings_and_comments_carry_no_measurements_or_history():
    found = []
    for path in _sources():
        for line, kind, text in _texts(path):
            for name in offences(text):
                found.append(f"{path.relative_to(ROOT)}:{line}: {kind} with {name}")
    assert not found, "\n".join(found)


@pytest.mark.parametrize("text", [
    # from the docstrings and comments these checks were written against
    "less forward time from N ~ 24 on (1.6x at N = 24: 0.056 s vs 0.089 s;",
    "a gradient 2.6x faster at N = 48 (15 s vs 40 s with compilation).",
    "RATTLE (the default; forward time after compiling, 2026-12-02) and Tsit5 at 0.15 h^2 (2026-11):",
    "to 26.135 deg, v_s = 37.7720 v* (check 37.7290, 0.11 %); 93.1 s in all, compilation included.",
    ("made the vmapped phase diagram run the homotopy at every gap (measured 0.2 s per gap at\n"
     "    5 Psi0, N = 100, instead of 3 ms)."),
    ("# Measured at N = 100, 3 right-hand sides, per batched solve inside a compiled loop\n"
     "# (2026-12-02, 2 cores): B = 4: loop 13.7 us, scan 81 us (batched LAPACK 12.4 us);"),
    "skipping it saves about a quarter of the run (N = 60 + 120: 116 ms ->\n    85 ms on 2 cores)",
    "and costs nothing measurable here (snap_angles at N = 100: 72 ms with, 76 ms without).",
    "them concurrently on the two threads of a 2-core machine",
    "Measured on 2 CPU cores at n = 100 (fold-height residual + Jacobian)",
    "the phase diagram ran 2.1x faster than one device",
    "Tsit5 at 1e-10 was too slow at N = 200 on this machine",
    "(a snap-angles run spends ~20 s compiling and well under 1 s computing)",
    "One small jitted program (0.1 s to compile) rather than a dozen eager operations",
    "a corrector pass at N = 100 costs about 45 us alone and 31 us per member in a batch of 128",
    "Homotopy (51 ms of 93 ms per scene at N = 100) was most of the cost",
    "N = 100): the vmapped call 3.98 s, the sequential chunks 2.70 s, so `batch=\"auto\"` picks",
    "64 starts took 5.61 s as one `vmap` (11.4 designs/s), 2.58 s in chunks of 8",
    "the trade: 1.7x less time at N = 50",
    "each evaluation is one `snap_angles` call (~0.3 s at n = 100).",
    "(16384 cost 18 % more time at N = 100 for the same v_s to 1e-5)",
    "A/B in this session",
    "added at stop 12 of the review",
    "Conventions (see MODEL.md): arclength $s\\in[0,L]$",
    "Conventions (see ../shared/MODEL.md)",
])
def test_detector_flags_measurements_and_history(text):
    assert offences(text), text


@pytest.mark.parametrize("text", [
    r"$v_s$ in units of $v^\ast$ ($v^\ast=L/T$)",
    "t1 = 5 T",
    "dt = 1e-4 T, t1 = 2.4 T, 13.4 T in all",
    "a step of 0.45 (h/L)^2 T; RATTLE is stable below 0.5 h^2",
    "Conventions (see docs/model.md): arclength s in [0, L]",
    ("the optimized compile costs a few times the fast one and roughly halves the run time; "
     "see benchmarks/results/compile.md"),
    "energy error 4.0e-3 over 5.6 T at N = 50, 3.6e-3 over 6 T at N = 100",
    "Tsit5 stable at $dt=10^{-4}=0.23\\,h^2$, unstable at $2\\times10^{-4}$",
    "`s0s` holds the fold widths; `vs` the snap speeds",
    "the CPU's cores run the members one after another",
    "a 13-shift count at once would be a 13x wider batched solve",
    "decided without a snap, but not at the parameter bound (`STOP_BOUND`): the continuation stopped",
    "v_s = 37.7720 v* (check 37.7290, 0.11 %), Psi0 = 26.135 deg",
    "jaxlib 0.10.2; N = 2048-1024 segments",
    "a physical strip: T = 12 ms. The snap takes 0.3 T",
    r"so $\gamma=-2s$, $s$ the slope of $\ln$ of the peaks",
    r"the even quartic $\tfrac38\epsilon+\tfrac34 s^2/\epsilon-\tfrac18 s^4/\epsilon^3$ below",
    "the quartic 3/8 eps + 3/4 s^2/eps - 1/8 s^4/eps^3",
])
def test_detector_passes_product_text(text):
    assert offences(text) == [], text
