"""``composed-sim join``: a machine's block of robots for a simulator started with ``run --machines``;
``composed-sim credentials make``: the TLS credentials of such runs, made beforehand."""
from __future__ import annotations

import sys

from composed_sim.cli.common import Interrupts
from composed_sim.command_line import EXIT_INTERRUPTED, UserError


def join_credentials(args):
    """The credentials a join presents: the file for tls://, none for tcp:// with --insecure; a
    UserError for any other pairing (a machine is never talked into plain TCP by an address)."""
    from composed_sim.hosting import HostError
    from composed_sim.hosts.machines.credentials import load
    scheme = args.address.split("://", 1)[0] if "://" in args.address else ""
    if scheme == "tcp" or args.insecure:
        if not (scheme == "tcp" and args.insecure):
            raise UserError(f"{args.address}: plain tcp:// and --insecure go together (a run started with "
                            f"--insecure prints both); a run with TLS is at tls://HOST:PORT")
        if args.credentials is not None:
            raise UserError("--credentials: not with --insecure (plain tcp:// uses none)")
        print("composed-sim join: --insecure: plain tcp://, neither authenticated nor encrypted: this machine "
              "takes work from whoever answers at that address", file=sys.stderr)
        return None
    if scheme != "tls":
        raise UserError(f"{args.address}: expected tls://HOST:PORT, as the simulator printed it")
    if args.credentials is None:
        raise UserError(f"{args.address}: needs --credentials FILE, the run's credentials (the simulator printed "
                        f"the command with it)")
    try:
        return load(args.credentials)
    except HostError as e:
        raise UserError(f"--credentials {e}") from None


def cmd_join(args) -> int:
    """A machine of a run: serves until the run ends (0) or Ctrl-C/SIGTERM (130)."""
    from composed_sim.hosting import HostError
    from composed_sim.hosts.machines.cluster import join
    credentials = join_credentials(args)
    print(f"composed-sim join: looking for the simulator at {args.address}" + (f" (run {args.run})" if args.run else ""), file=sys.stderr)
    with Interrupts("leaving the run") as interrupts:
        try:
            ended = join(args.address, args.run, args.workers, args.timeout, lambda: interrupts.requested,
                         credentials)
        except HostError as e:
            raise UserError(str(e)) from None
    print(f"composed-sim join: {ended}; done", file=sys.stderr)
    return EXIT_INTERRUPTED if ended == "stopped" else 0


def cmd_credentials(args) -> int:
    """``credentials make DIR``: new credentials in DIR/credentials.pem, its path printed."""
    from composed_sim.hosting import HostError
    from composed_sim.hosts.machines.credentials import FILE_NAME, make
    path = args.dir / FILE_NAME
    try:
        make(path)
    except HostError as e:
        raise UserError(str(e)) from None
    except OSError as e:
        raise UserError(f"{path}: {e.strerror or e}") from None
    print(path)
    print(f"composed-sim credentials: whoever holds {path} may join the runs started with it (run --machines … "
          f"--credentials {path}); keep it private, make new ones to revoke it", file=sys.stderr)
    return 0
