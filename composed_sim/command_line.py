"""What the ``composed-sim`` subcommands share: the one-line user error, argument types, checks."""
from __future__ import annotations

import argparse
import tempfile
from pathlib import Path


EXIT_FAILED = 1      # the run could not go on (a full disk); what it wrote is kept
EXIT_USAGE = 2       # bad input: world file, plugin, CLI value
EXIT_INTERRUPTED = 130


class UserError(Exception):
    """A mistake in what the user gave us: reported as one line, never a traceback."""


class RunStopped(Exception):
    """The machine stopped the run (a full disk): one line saying why and what was kept, exit
    EXIT_FAILED."""


def number_arg(kind: type, *, minimum: float, inclusive: bool = True):
    """An argparse type: a whole number (kind=int) or a number, at least (or above) ``minimum``."""
    def parse(text: str):
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(
                f"expected a {'whole ' if kind is int else ''}number, got {text!r}") from None
        if not (value >= minimum if inclusive else value > minimum):
            raise argparse.ArgumentTypeError(f"must be {'>=' if inclusive else '>'} {minimum:g} (got {text})")
        return value
    return parse


def check_writable(out: Path) -> None:
    """An output directory that can be created and written, or one UserError naming it. Creates
    nothing: a run that fails before it writes leaves no empty folder behind."""
    existing = out
    while not existing.exists() and existing != existing.parent:
        existing = existing.parent
    if not existing.is_dir():
        raise UserError(f"--out {out}: cannot write there (Not a directory)")
    try:
        with tempfile.TemporaryFile(dir=existing):
            pass
    except OSError as e:
        raise UserError(f"--out {out}: cannot write there ({e.strerror or e})") from None
