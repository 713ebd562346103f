"""The command line's one error path.

A *user* error (a bad value, a missing or foreign file, a file where a folder belongs) is one
line ``error: ...`` on stderr and exit code 2, with nothing left behind; an *internal* error
(a bug) is one line too, but exit code 1 and a hint: ``persival --debug ...`` re-raises it with
its traceback. Every stage's ``commands.py`` uses :func:`user_errors` and :func:`fail`; the main
app is a :class:`ErrorReportingGroup`.
"""

from __future__ import annotations

import os
import shutil
import sys
from collections.abc import Iterator
from contextlib import contextmanager, suppress
from pathlib import Path

import typer
import typer.exceptions

from persival.cli.help import FullHelpGroup

__all__ = ["USER_ERRORS", "ErrorReportingGroup", "fail", "user_errors", "check_output_dir", "check_output_file"]

#: What counts as a user error everywhere; stages add their own (StoreError, ...) per call.
USER_ERRORS: tuple[type[BaseException], ...] = (ValueError, FileNotFoundError, NotADirectoryError,
                                                IsADirectoryError, FileExistsError)

# typer >= 0.2x vendors click: its Exit, Abort and usage errors (TyperException) are its own
# classes, not the installed click's. They carry their own reporting and exit code.
_EXITS = (typer.Exit,)
_PASS_THROUGH = (typer.Exit, typer.Abort, typer.exceptions.TyperException)

EXIT_USER_ERROR = 2
EXIT_INTERNAL_ERROR = 1


def _one_line(message: str) -> str:
    # Pydantic and some OS errors span several lines; the contract is one line.
    text = ""
    for part in (p.strip() for p in str(message).splitlines()):
        if part:
            text += part if not text else (" " if text.endswith(":") else "; ") + part
    return text


def _message(exc: BaseException) -> str:
    if isinstance(exc, OSError) and exc.filename is not None and exc.strerror:
        return f"{exc.filename}: {exc.strerror.lower()}"  # not "[Errno 2] No such file ..."
    if isinstance(exc, KeyError) and type(exc).__str__ is KeyError.__str__ and exc.args:
        return str(exc.args[0])  # KeyError quotes its message
    return str(exc) or type(exc).__name__


def fail(message: str) -> None:
    """Print ``error: message`` on stderr and exit with code 2."""
    typer.echo(f"{typer.style('error:', fg='red', bold=True)} {_one_line(message)}", err=True)
    raise typer.Exit(EXIT_USER_ERROR)


@contextmanager
def user_errors(*extra: type[BaseException], out: Path | None = None) -> Iterator[None]:
    """Turn user errors raised inside the block into :func:`fail`.

    ``extra``: the stage's own user-error classes (e.g. StoreError, which is a RuntimeError).
    ``out``: an output path the block may create; if it did not exist before, it is removed
    again when the block ends in a user error or a non-zero exit, so that a rejected command
    leaves nothing behind. An internal error or Ctrl-C keeps it: partial results help debugging
    and a campaign store can be resumed.
    """
    created = out is not None and not Path(out).exists()
    try:
        yield
    except _EXITS as exc:
        if created and exc.exit_code:
            _remove(Path(out))
        raise
    except USER_ERRORS + extra as exc:
        if created:
            _remove(Path(out))
        fail(_message(exc))


def _remove(path: Path) -> None:
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path, ignore_errors=True)
    elif path.exists() or path.is_symlink():
        path.unlink()


def check_output_dir(path: Path, what: str = "--out") -> Path:
    """``path`` can become an output folder: it is one already, or nothing is there yet."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise NotADirectoryError(f"{what} {path} is a file, not a folder")
    for parent in path.parents:
        if parent.exists():
            if not parent.is_dir():
                raise NotADirectoryError(f"{what} {path}: {parent} is a file, not a folder")
            break
    return path


def check_output_file(path: Path, what: str = "--out") -> Path:
    """``path`` can become an output file: not a folder, and its parent is not a file."""
    path = Path(path)
    if path.is_dir():
        raise IsADirectoryError(f"{what} {path} is a folder, not a file")
    check_output_dir(path.parent, what)
    return path


def _is_usage_error(exc: BaseException) -> bool:
    """click's usage errors (a bad value, an unknown option, a missing argument): exit code 2 and
    the context of the command whose options they are (typer vendors click, so no public class)."""
    return getattr(exc, "exit_code", None) == EXIT_USER_ERROR and getattr(exc, "ctx", None) is not None


class ErrorReportingGroup(FullHelpGroup):
    """The main app's group: an exception that is not a user error becomes one line and exit 1,
    unless ``--debug`` was given, which lets it through with its traceback."""

    def invoke(self, ctx):
        try:
            return super().invoke(ctx)
        except typer.exceptions.TyperException as exc:
            if _is_usage_error(exc):  # a subcommand's bad option: one line, not click's usage block
                where = exc.ctx.command_path
                typer.echo(f"{typer.style('error:', fg='red', bold=True)} {where}: {_one_line(exc.format_message())} "
                           f"(`{where} --help` lists the options)", err=True)
                raise typer.Exit(EXIT_USER_ERROR) from None
            raise
        except _PASS_THROUGH:
            raise
        except BrokenPipeError:  # the reader went away (`persival --help | head`): nothing to report
            with suppress(OSError):  # no real stdout (a test runner): nothing to silence
                os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # nor at interpreter exit
            raise typer.Exit(EXIT_INTERNAL_ERROR) from None
        except Exception as exc:
            if ctx.params.get("debug"):
                raise
            typer.echo(f"{typer.style('internal error:', fg='red', bold=True)} {type(exc).__name__}: "
                       f"{_one_line(_message(exc))} (run `persival --debug ...` for the traceback)", err=True)
            raise typer.Exit(EXIT_INTERNAL_ERROR) from None
