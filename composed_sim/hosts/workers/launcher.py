"""The worker processes of the worker host: a block of robots in one participant group, one executor.

``python -m composed_sim.hosts.workers.launcher --fds N1,N2,… --logs DIR --parent-pid P`` is started
by ``hosts/workers/worker_host.py`` as a launcher: it imports what a worker needs once (serving.py),
forks one worker per socket, prints their pids and exits. Forking spares each worker the
interpreter's start and the imports (docs/speed.md, "Set-up"), and the workers share those pages
in memory. The main process,
a subreaper, adopts the workers when the launcher exits (hosts/processes.py, ``AdoptedChild``).

A worker talks to the main process over its socket (pickled messages,
``multiprocessing.connection``), once per tick each way:

    main → worker   ("setup", WorkerSetup)         once, first
                    ("served", calls, tick)        before tick 0: what every place serves, and the
                                                   tick of the run-wide nodes' first timer
                    ("tap", [glob, …])             record these topics' messages (--record-topics)
                    ("tick", tick, routed, changed, batch)  a tick: the world's state is in the
                                                   shared state (shared_state.py); what changed of
                                                   the scene, floor and lights; the run-wide
                                                   messages that open it (hosting/run_wide/relay.py)
                    ("clock", tick)                /clock alone, for the state after the last tick
                    ("stop",)                      end now
    worker → main   ("ready", nodes, messages)     discovery done: tick 0 can start; what its nodes
                                                   published on run-wide topics while being built
                    ("error", kind, message, field, user_traceback) the block could not be built
                    ("answers", TickAnswers)       the tick's LEDs, payloads, violations (its
                                                   commands: in the shared state),
                                                   and its nodes' console lines (hosting/guard/node_logs.py)

Inside, a tick is exactly the single-process host's: the worker reads its block's sensors
(core/senses.py), its simulator node publishes them, the executor runs the controllers' callbacks until every robot answered or the watchdog
expired, and the simulator node's ``close_tick`` computes the commands with the fallbacks.

A worker dies with the main process (PR_SET_PDEATHSIG, SIGKILL included; the launcher too) and
ignores SIGINT: a terminal's Ctrl-C is for the main process, which stops at a tick boundary and
then stops the workers. Its stdout and stderr go to ``worker<i>.log`` in ``--logs``.
"""
from __future__ import annotations

import argparse
import gc
import os
import signal
import sys

from composed_sim.hosts.processes import die_with_parent


def main(argv: list[str] | None = None) -> int:
    """The launcher: import what a worker needs once, fork the K workers, tell the main process
    their pids (one line on stdout) and exit; the main process, a subreaper, adopts them."""
    p = argparse.ArgumentParser(prog="python -m composed_sim.hosts.workers.launcher")
    p.add_argument("--fds", required=True, help="the workers' socket descriptors, comma-separated, in worker order")
    p.add_argument("--logs", required=True, help="the folder of the workers' worker<i>.log")
    p.add_argument("--parent-pid", type=int, required=True)
    args = p.parse_args(argv)
    # SIGKILL, not SIGTERM: a worker has nothing to write, and must not linger in a callback.
    die_with_parent(args.parent_pid, signal.SIGKILL)
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})
    fds = [int(fd) for fd in args.fds.split(",")]

    from composed_sim.hosts.workers.serving import serve     # the imports, shared by every fork
    # The imported objects out of the collector's reach: its passes would write to every one of
    # them in every worker, copying the pages they share (1280 robots in 8 workers: peak PSS 1267
    # -> 1162 MB).
    gc.freeze()
    sys.stdout.flush()
    sys.stderr.flush()
    pids = []
    for index, fd in enumerate(fds):
        pid = os.fork()
        if pid == 0:
            code = 1
            try:
                _become_worker(index, fd, fds, args)
                code = serve(fd, lambda: die_with_parent(args.parent_pid, signal.SIGKILL))
            except SystemExit as e:     # die_with_parent: the main process was gone already
                code = e.code if isinstance(e.code, int) else 1
            except BaseException:    # noqa: BLE001 - a worker's last word: its traceback to the main process
                import traceback
                traceback.print_exc()
            finally:
                sys.stdout.flush()
                sys.stderr.flush()
                os._exit(code)
        try:
            os.setpgid(pid, pid)  # as the worker does itself: whichever runs first
        except OSError:           # it did, and is gone already: the main process will see why
            pass
        pids.append(pid)
    print(" ".join(map(str, pids)), flush=True)
    return 0


def _become_worker(index: int, fd: int, fds: list[int], args) -> None:
    """In a freshly forked worker: its own process group (the main process signals a worker's
    group), its own log as stdout and stderr, none of the other workers' sockets (a worker's
    death must close its socket). Its death with the main process is set once it is the main
    process's child (``serve``'s ``adopted``); until then a main process that dies closes its
    socket, which ends it."""
    os.setpgid(0, 0)
    log = os.open(os.path.join(args.logs, f"worker{index}.log"), os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o644)
    os.dup2(log, 1)
    os.dup2(log, 2)
    os.close(log)
    for other in fds:
        if other != fd:
            os.close(other)


if __name__ == "__main__":
    sys.exit(main())
