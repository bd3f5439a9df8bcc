"""The ``khepera-noise`` command: one subcommand per module in ``commands/``.

Each command module defines ``HELP`` (one line), ``add_arguments(parser)`` and
``run(args) -> int``; modules whose names start with ``_`` are shared helpers.
Errors a user can fix (``UsageError``, ``ValueError``, ``FileNotFoundError``)
are printed as one line and exit with status 2.
"""
from __future__ import annotations

import argparse
import importlib
import os
import pkgutil
import sys

from . import __version__, commands, files, lifeline
from .commands._options import UsageError


def loopback_only() -> None:
    """Keep DDS discovery on this machine unless the user already chose otherwise."""
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog='khepera-noise',
        description='Evolve Khepera light-centring controllers under Meeden (1998) sensor '
                    'noise models, test them on the robot, and diagnose the sim-to-real gap.')
    parser.add_argument('--version', action='version', version=f'%(prog)s {__version__}')
    sub = parser.add_subparsers(dest='command', metavar='COMMAND', required=True)
    for info in sorted(pkgutil.iter_modules(commands.__path__), key=lambda m: m.name):
        if info.name.startswith('_'):
            continue
        try:
            module = importlib.import_module(f'{commands.__name__}.{info.name}')
        except ImportError as exc:
            # one command missing an optional dependency must not take down the others
            p = sub.add_parser(info.name, help=f'(unavailable: {exc})')
            p.set_defaults(run=_unavailable(info.name, exc))
            continue
        name = getattr(module, 'NAME', info.name)
        p = sub.add_parser(name, help=module.HELP, description=module.__doc__,
                           formatter_class=argparse.ArgumentDefaultsHelpFormatter)
        module.add_arguments(p)
        p.set_defaults(run=module.run)
    return parser


def _unavailable(name: str, exc: ImportError):
    def run(args):
        raise UsageError(f'the {name} command cannot load: {exc}')
    return run


def main(argv=None) -> int:
    loopback_only()
    lifeline.from_environment()
    with lifeline.terminate_as_interrupt():         # kill (SIGTERM) saves what Ctrl-C saves
        try:
            args = build_parser().parse_args(argv)
        except KeyboardInterrupt:                   # stopped while loading the commands
            return 130
        status = _run(args)
    if status == 130 and argv is None:
        # stopped, and this process is the command: what it saves is written and closed,
        # so skip the interpreter's and DDS's teardown (seconds on a busy machine)
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(status)
    return status


def _run(args) -> int:
    try:
        return int(args.run(args) or 0)
    except (UsageError, ValueError, FileNotFoundError) as exc:
        print(f'khepera-noise {args.command}: error: {exc}', file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f'khepera-noise {args.command}: interrupted', file=sys.stderr)
        return 130
    except BrokenPipeError:
        # `khepera-noise ... | head`: the reader left; stop quietly like other CLI tools
        sys.stderr.close()
        return 0
    except OSError as exc:
        if not files.refused(exc):
            raise
        print(f'khepera-noise {args.command}: error: {files.describe(exc)}', file=sys.stderr)
        return 1


if __name__ == '__main__':
    sys.exit(main())
