# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""The `tofmat` command's error boundary, exit statuses, verbosity and progress bars.

Every command of the `tofmat` group (and of its sub-groups) runs inside one boundary:

- a user error (bad option values, an unknown material, a file that is missing or may not be
  read, a malformed file) is one line on stderr and exit status 2;
- a failure of the system (the daemon unreachable, the camera gone, a disk error, a bug) is one
  line on stderr and exit status 1;
- ``-v`` adds the traceback and debug logs, ``-q`` silences progress bars.
"""

from __future__ import annotations

import errno
import logging
import math
import signal
import sys
import threading
import traceback
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any

import click

from ._progress import Progress

EXIT_OK = 0
EXIT_FAILURE = 1
EXIT_USAGE = 2

EXIT_STATUS_HELP = "Exit status: 0 success, 1 failure (of the daemon, the camera, the system), 2 usage error."

# OSErrors that say something about what the user named (a path), not about the system.
_USER_ERRNOS = {errno.ENOENT, errno.EACCES, errno.EPERM, errno.EISDIR, errno.ENOTDIR, errno.EEXIST, errno.ENAMETOOLONG}


class UserError(click.ClickException):
    """Bad input from the user: one line, exit status 2."""

    exit_code = EXIT_USAGE


class Failure(click.ClickException):
    """The system failed (not the user's input): one line, exit status 1."""

    exit_code = EXIT_FAILURE


@dataclass
class CliState:
    """What the top-level options set for every command: ``-v`` and ``-q``."""

    verbose: bool = False
    quiet: bool = False


def state() -> CliState:
    """The running command's CliState (defaults outside a command, as in a library call)."""
    ctx = click.get_current_context(silent=True)
    obj = ctx.find_object(CliState) if ctx else None
    return obj or CliState()


def _one_line(text: str) -> str:
    lines = [ln.strip() for ln in text.strip().splitlines() if ln.strip()]
    return "; ".join(lines) if lines else "(no message)"


def classify_exception(e: BaseException) -> click.ClickException:
    """The one-line message and exit status for an exception a command let through."""
    from ._extras import MissingExtraError
    from ._tofmat import ClientError

    if isinstance(e, MissingExtraError):
        return Failure(_one_line(str(e)))
    # Before OSError: DaemonTimeoutError and DaemonUnavailableError are OSErrors too. What the daemon
    # refused as an invalid argument is the user's; a timeout, a refusal, a bad peer are failures.
    if isinstance(e, ClientError):
        code = getattr(e, "code", "")
        return UserError(_one_line(str(e))) if code == "invalid_argument" else Failure(_one_line(str(e)))
    if isinstance(e, KeyError):  # an unknown name (material, stream): str() of a KeyError quotes it
        return UserError(_one_line(str(e.args[0]) if e.args else "unknown key"))
    if isinstance(e, OSError):
        # OSError(errno, message) prints as "[Errno 2] message": the message alone says it, with a path.
        what = _one_line(e.strerror if e.strerror and e.filename is None and "/" in e.strerror else str(e))
        # Our own OSErrors (no errno) are about what a named path holds; the system's carry an errno,
        # and those of a path (FileNotFoundError, PermissionError, ...) are the user's.
        return UserError(what) if e.errno is None or e.errno in _USER_ERRNOS else Failure(what)
    if isinstance(e, (ValueError, TypeError)):  # FormatError is a ValueError; TypeError: an array of no numbers
        return UserError(_one_line(str(e)))
    if isinstance(e, (RuntimeError, ConnectionError, TimeoutError)):
        return Failure(_one_line(str(e)))
    return Failure(f"internal error: {type(e).__name__}: {_one_line(str(e))} (run with -v for the traceback)")


class FiniteFloat(click.FloatRange):
    """A float within a range that is never NaN or infinite (click's FloatRange lets NaN through)."""

    name = "finite float"

    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None) -> Any:
        rv = super().convert(value, param, ctx)
        if not math.isfinite(rv):
            self.fail(f"{value!r} is not a finite number.", param, ctx)
        return rv


class NumberList(click.ParamType):  # type: ignore[type-arg]
    """A comma-separated list of numbers, each within [lo, hi]: "1,3,10"."""

    name = "list"

    def __init__(self, kind: type[int] | type[float], lo: float, hi: float) -> None:
        self.kind, self.lo, self.hi = kind, lo, hi

    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None) -> Any:
        if isinstance(value, list):
            return value
        try:
            items = [self.kind(v.strip()) for v in str(value).split(",") if v.strip()]
        except ValueError:
            items = []
        if not items or not all(math.isfinite(v) and self.lo <= v <= self.hi for v in items):
            what = "whole numbers" if self.kind is int else "numbers"
            self.fail(f"{value!r}: expected comma-separated {what} from {self.lo:g} to {self.hi:g}", param, ctx)
        return items


def _terminated(signum: int, frame: object) -> None:
    raise SystemExit(128 + signal.SIGTERM)


class TofmatCommand(click.Command):
    """A command whose help ends with the exit statuses (groups too: click.Group is a Command)."""

    def format_epilog(self, ctx: click.Context, formatter: click.HelpFormatter) -> None:
        super().format_epilog(ctx, formatter)
        formatter.write_paragraph()
        formatter.write_text(EXIT_STATUS_HELP)


class TofmatGroup(TofmatCommand, click.Group):
    """A group whose commands (and sub-groups) run inside the error boundary."""

    command_class = TofmatCommand
    group_class = type  # sub-groups are TofmatGroups too

    def main(
        self,
        args: Sequence[str] | None = None,
        prog_name: str | None = None,
        complete_var: str | None = None,
        standalone_mode: bool = True,
        **extra: Any,
    ) -> Any:
        """Runs the command line; in standalone mode every error is one line on stderr and its exit status."""
        if not standalone_mode:
            return super().main(args, prog_name, complete_var, standalone_mode=False, **extra)
        # SIGTERM (systemd, kill, a CI's timeout) ends a command as Ctrl-C does: its `finally` and `with`
        # blocks run (children stopped, temporaries removed), then status 143 (128 + 15).
        if threading.current_thread() is threading.main_thread():
            signal.signal(signal.SIGTERM, _terminated)
        try:
            rv = super().main(args, prog_name, complete_var, standalone_mode=False, **extra)
        except click.UsageError as e:  # one line, with where to find help, instead of click's three
            hint = f" (see '{e.ctx.command_path} --help')" if e.ctx is not None else ""
            click.echo(f"Error: {_one_line(e.format_message())}{hint}", err=True)
            sys.exit(EXIT_USAGE)
        except click.ClickException as e:
            click.echo(f"Error: {_one_line(e.format_message())}", err=True)
            sys.exit(e.exit_code)
        except click.Abort:
            click.echo("Aborted.", err=True)
            sys.exit(EXIT_FAILURE)
        except KeyboardInterrupt:
            sys.exit(130)
        sys.exit(rv if isinstance(rv, int) else EXIT_OK)

    def invoke(self, ctx: click.Context) -> Any:
        try:
            return super().invoke(ctx)
        except (click.ClickException, click.exceptions.Exit, click.Abort, KeyboardInterrupt, SystemExit):
            raise
        except Exception as e:
            if ctx.parent is not None:  # the root group reports it, once
                raise
            if state().verbose:
                traceback.print_exception(e, file=sys.stderr)
            raise classify_exception(e) from e


@contextmanager
def progress_bar(label: str) -> Iterator[Progress]:
    """A progress bar on stderr with what is being done and the time left (none with -q).

    The total is learnt from the first call, so the work's own code says how many steps it has.
    A bar is drawn only on a terminal: a log or a pipe gets the command's results, not its progress.
    """
    quiet = state().quiet or not sys.stderr.isatty()
    bar: Any = None
    shown = 0

    def update(done: int, total: int, what: str = "") -> None:
        nonlocal bar, shown
        if quiet:
            return
        if bar is None:
            bar = click.progressbar(
                length=max(total, 1), label=label, show_eta=True, show_pos=True, file=sys.stderr,
                item_show_func=lambda item: item,
            )  # fmt: skip
            bar.__enter__()
        step = max(0, done - shown)
        shown += step
        bar.update(step, what or None)

    try:
        yield update
    finally:
        if bar is not None:
            bar.__exit__(None, None, None)


def setup_logging(verbose: bool) -> None:
    """Warnings by default; -v shows debug logs of the SDK and of the C++ core (both through logging)."""
    logging.basicConfig(
        level=logging.DEBUG if verbose else logging.WARNING, format="%(levelname)s %(name)s: %(message)s"
    )
    # A command's failure already says what the core last warned of (for example why the camera
    # could not be opened), in its one line: the core's own warnings are for -v.
    logging.getLogger("tofmat.core").setLevel(logging.DEBUG if verbose else logging.ERROR)
    from . import _tofmat

    _tofmat.forward_core_logs()  # the core takes the level now


__all__ = [
    "EXIT_FAILURE",
    "EXIT_OK",
    "EXIT_STATUS_HELP",
    "EXIT_USAGE",
    "CliState",
    "Failure",
    "FiniteFloat",
    "NumberList",
    "Progress",
    "TofmatCommand",
    "TofmatGroup",
    "UserError",
    "classify_exception",
    "progress_bar",
    "setup_logging",
    "state",
]


def strict_json(value: Any) -> Any:
    """``value`` with every infinite or NaN float as a string ("inf", "nan"): JSON has no such numbers."""
    if isinstance(value, float) and not math.isfinite(value):
        return str(value)
    if isinstance(value, dict):
        return {k: strict_json(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [strict_json(v) for v in value]
    return value
