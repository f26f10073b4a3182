"""The host that ``HostSettings`` ask for, in ROS domains of the run's own: what ``composed-sim
run`` and ``composed-sim replay --check`` start (each mode's module is imported when chosen)."""
from __future__ import annotations

from dataclasses import replace
from typing import Optional

from composed_sim.hosting import NodeLogs
from composed_sim.hosts.domain_claim import DomainClaim, claim_domains, claim_free_domain, run_identity
from composed_sim.hosts.base import Host
from composed_sim.hosts.settings import AUTO_WORKERS, HostSettings
from composed_sim.world.schema import World


def worker_count(settings: HostSettings, world: World) -> int:
    """The composed host's worker processes: as given, or for --workers auto from the swarm."""
    from composed_sim.hosts.workers.worker_host import auto_workers
    return auto_workers(len(world.robot_names())) if settings.workers == AUTO_WORKERS else settings.workers


def make_host(settings: HostSettings, world: World, logs: Optional[NodeLogs] = None) -> Host:
    """The host, not entered yet. ``logs``: where the nodes' log lines go (hosting/guard/node_logs.py)."""
    if settings.discovery is not None:
        from composed_sim.hosts.discovery import describe
        from composed_sim.hosts.outside_controllers import OutsideControllersHost
        return OutsideControllersHost(world, domain_id=settings.domain_id,
                                      discovery_timeout_s=settings.discovery.timeout_s, discovery=describe())
    if settings.machines is not None:
        from composed_sim.hosts.machines.remote_host import RemoteWorkerHost
        return RemoteWorkerHost(world, machines=settings.machines, listen=settings.listen, link=settings.link,
                                executor=settings.executor,
                                domain_id=settings.domain_id, logs=logs, join_timeout_s=settings.join_timeout_s)
    if settings.mode == "multi-process":
        from composed_sim.hosts.multiprocess.multiprocess_host import MultiProcessHost
        return MultiProcessHost(world, executor=settings.executor, domain_id=settings.domain_id,
                                robots_per_domain=settings.robots_per_domain, logs=logs)
    workers = worker_count(settings, world)
    if workers == 1:
        from composed_sim.hosts.composed import ComposedHost
        return ComposedHost(world, executor=settings.executor, domain_id=settings.domain_id,
                            robots_per_participant=settings.robots_per_participant, logs=logs)
    from composed_sim.hosts.workers.worker_host import WorkerHost
    return WorkerHost(world, workers=workers, executor=settings.executor, domain_id=settings.domain_id, logs=logs)


def host_in_own_domains(settings: HostSettings, world: World,
                        logs: Optional[NodeLogs] = None) -> tuple[Host, DomainClaim, bool]:
    """The host, its ROS domains claimed for the run (hosts/domain_claim.py): a given domain must
    be free (DomainTaken), else the first free block is taken and the host built there. Also
    whether the domains were picked so (the caller says which)."""
    host = make_host(settings, world, logs)
    used = host.ros_domains()
    # A world's multi_process.first_domain is given too.
    given = settings.domain_given or used[0] != settings.domain_id
    about = run_identity(world.name)
    controllers_first = settings.discovery is not None     # outside controllers may be up already
    if given:
        return host, claim_domains(used, about, given=True, controllers_expected=controllers_first), False
    claim, first = claim_free_domain(len(used), about, controllers_expected=controllers_first)
    return make_host(replace(settings, domain_id=first), world, logs), claim, True
