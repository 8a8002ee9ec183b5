"""Shared pieces of the fuzz suite: the one-line-error property, a per-case time limit,
the settings every fuzz test uses and the case counter the session summary prints.

The property (issue 17): whatever a loader is given, it returns, or raises a
:class:`~voxwarp.errors.VoxwarpError` whose message is one non-empty line; any other
exception is a traceback a user would see, and escapes to fail the test. Warnings voxwarp
itself emits are held to the same one-line rule. A case that runs longer than
:data:`CASE_SECONDS` fails as a hang.
"""

from __future__ import annotations

import contextlib
import io
import re
import signal
import warnings
from collections import Counter
from collections.abc import Callable, Iterator, Sequence
from typing import Any

from hypothesis import HealthCheck, event, settings
from hypothesis.control import currently_in_test_context

from voxwarp.errors import VoxwarpError

#: wall-clock limit of one generated case (seconds); the slowest legitimate case (a tiny
#: render through the CLI) takes well under a second
CASE_SECONDS = 20.0

#: the error line of the command line: ``voxwarp: error:`` or ``voxwarp render: error:``
ERROR_LINE = re.compile(r"^voxwarp(?: [a-z]+)?: error: ")
#: generated cases per test name, for the session summary (tests/fuzz/conftest.py)
CASES: Counter[str] = Counter()
#: how the cases ended, per test name: "ok", "error" (a one-line VoxwarpError), ...
OUTCOMES: dict[str, Counter[str]] = {}


def fuzz_settings(max_examples: int) -> settings:
    """Deterministic settings: derandomized, no example database, no deadline (the
    per-case limit is :func:`time_limit`), quiet about slow or filtered data."""
    return settings(
        max_examples=max_examples,
        deadline=None,
        derandomize=True,
        database=None,
        print_blob=True,
        suppress_health_check=[
            HealthCheck.too_slow,
            HealthCheck.filter_too_much,
            HealthCheck.data_too_large,
            HealthCheck.function_scoped_fixture,
        ],
    )


class CaseTimeout(BaseException):
    """A generated case ran past :data:`CASE_SECONDS` (a hang). A BaseException, so the
    ``except Exception`` wrappers of the loaders cannot turn it into a VoxwarpError."""


@contextlib.contextmanager
def time_limit(seconds: float = CASE_SECONDS) -> Iterator[None]:
    """Raise :class:`CaseTimeout` in the block after ``seconds`` (SIGALRM, main thread)."""

    def on_alarm(signum: int, frame: Any) -> None:
        raise CaseTimeout(f"the case ran longer than {seconds} s (a hang)")

    old = signal.signal(signal.SIGALRM, on_alarm)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)


def assert_one_line(message: str, what: str) -> None:
    """``message`` is one non-empty line."""
    assert message.strip(), f"{what} with an empty message"
    assert "\n" not in message, f"{what} spans lines: {message!r}"
    assert "\r" not in message, f"{what} holds a carriage return: {message!r}"


def _own_warning(w: warnings.WarningMessage) -> bool:
    name = w.filename.replace("\\", "/")
    return "/app/" in name or "/deform/" in name or "/voxwarp/" in name


def outcome(test: str, call: Callable[[], Any], also: tuple[type[Exception], ...] = ()) -> str:
    """Run ``call`` under the time limit and check the property; count the case.

    Returns ``"ok"`` or ``"error"`` (a one-line VoxwarpError, or one of ``also``: the
    ArgumentTypeError of an option's parser, which argparse prints as the error line);
    any other exception propagates (the bug the suite looks for), so does :class:`CaseTimeout`.
    """
    CASES[test] += 1
    result = "ok"
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            with time_limit():
                call()
        except (VoxwarpError, *also) as exc:
            assert_one_line(str(exc), type(exc).__name__)
            result = "error"
    for w in caught:
        if _own_warning(w):
            assert_one_line(str(w.message), f"warning {w.category.__name__}")
    _record(test, result)
    return result


def _record(test: str, result: str) -> None:
    OUTCOMES.setdefault(test, Counter())[result] += 1
    if currently_in_test_context():  # hypothesis' statistics (--hypothesis-show-statistics)
        event(result)


def cli_outcome(test: str, argv: Sequence[str]) -> str:
    """Run ``voxwarp ARGV`` in this process and check the command-line contract.

    Exit 0, or exit 2 with exactly one ``voxwarp: error:`` line on stderr (``voxwarp
    render: error:`` from argparse's sub-command parsers), as its last line (argparse
    puts its usage lines before it), and never a traceback: any exception
    other than SystemExit escapes :func:`voxwarp.cli.main.main`, and propagates here.
    """
    from voxwarp.cli.main import main

    CASES[test] += 1
    out, err = io.StringIO(), io.StringIO()
    with warnings.catch_warnings():
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err), time_limit():
            try:
                code = main(list(argv))
            except SystemExit as exc:  # argparse: usage + one error line, exit 2
                code = exc.code if isinstance(exc.code, int) else 1
    text = err.getvalue()
    assert "Traceback" not in text, text
    lines = [line for line in text.splitlines() if line.strip()]
    errors = [line for line in lines if ERROR_LINE.match(line)]
    if code == 0:
        assert not errors, text
        result = "ok"
    else:
        assert code == 2, f"exit code {code}; stderr: {text}"
        assert len(errors) == 1, f"expected one 'voxwarp: error:' line: {text}"
        assert lines[-1] == errors[0], f"the error line is not the last: {text}"
        assert ERROR_LINE.sub("", errors[0]).strip(), "an empty error line"
        result = "error"
    _record(test, result)
    return result
