"""Spreading robots over ROS domains for multi-process mode (pure: no ROS import).

Why domains at all: every controller process is a DDS participant, and Fast DDS gives each
participant of a domain its own UDP ports (discovery and user traffic, unicast) computed from
the domain id and the participant's index. The paper spread 50 robots per domain for that
reason; we do the same, with the simulator process joining each used domain once.

The valid range follows from the RTPS port formula Fast DDS uses (PB = 7400, DG = 250, PG = 2,
d1 = 10, d3 = 11): participant ``p`` of domain ``d`` listens on ``7400 + 250 d + 10 + 2 p`` and
``… + 11 + 2 p``. Ports must stay below 65536, so 232 is the largest usable domain
(7400 + 250 · 232 = 65400), and that last domain only fits 63 participants. In every other domain
index 120 would reach the next domain's ports (7400 + 250 (d + 1)), so a domain holds at most
120 participants: the simulator plus 119 controllers. (Domains ~102–214 also overlap Linux's
ephemeral port range 32768–60999; they work unless another program happens to hold a port.)
"""
from __future__ import annotations

from typing import Iterable, Optional

from composed_sim.world.schema import MAX_DOMAIN

MIN_DOMAIN = 0
_PORT_BASE, _DOMAIN_GAIN, _PARTICIPANT_GAIN = 7400, 250, 2
_META_UNICAST_OFFSET, _USER_UNICAST_OFFSET = 10, 11
# 120: participant 120's first port, 7410 + 250 d + 240, is the next domain's first port.
MAX_PARTICIPANTS_PER_DOMAIN = (_DOMAIN_GAIN - _META_UNICAST_OFFSET) // _PARTICIPANT_GAIN
SIMULATOR_PARTICIPANTS = 1            # the simulator process joins each used domain once


class DomainError(ValueError):
    """The robots cannot be spread over valid domains; the message says why and what to change."""


def capacity(domain: int) -> int:
    """Controller processes (robots) that fit in ``domain`` next to the simulator's participant."""
    last_port = _PORT_BASE + _DOMAIN_GAIN * domain + _USER_UNICAST_OFFSET
    participants = min(MAX_PARTICIPANTS_PER_DOMAIN, (65535 - last_port) // _PARTICIPANT_GAIN + 1)
    return participants - SIMULATOR_PARTICIPANTS


def assign_domains(names: Iterable[str], robots_per_domain: int, first_domain: int,
                   explicit: Optional[dict[str, int]] = None) -> dict[str, int]:
    """Robot name → ROS domain.

    Robots listed in ``explicit`` go to their domain. The others, in order, fill domains
    ``first_domain``, ``first_domain + 1``, … with ``robots_per_domain`` robots each (counting
    the explicitly placed ones; fewer in domain 232, which has fewer ports), as the paper's
    "50 robots per domain": bot0–bot49 in the first.
    """
    names = list(names)
    explicit = dict(explicit or {})
    n = len(names)
    if not 1 <= robots_per_domain <= capacity(0):
        raise DomainError(f"robots per domain must be within 1..{capacity(0)}: Fast DDS fits "
                          f"{MAX_PARTICIPANTS_PER_DOMAIN} participants in a domain, one of them the "
                          f"simulator (got {robots_per_domain})")
    if not MIN_DOMAIN <= first_domain <= MAX_DOMAIN:
        raise DomainError(f"first domain {first_domain} is outside the valid ROS domain ids "
                          f"{MIN_DOMAIN}..{MAX_DOMAIN}")
    unknown = sorted(set(explicit) - set(names))
    if unknown:
        raise DomainError(f"multi_process.domains names robots the world does not have: "
                          f"{', '.join(unknown)} (robots are {_span(names)})")
    bad = {r: d for r, d in explicit.items() if not MIN_DOMAIN <= d <= MAX_DOMAIN}
    if bad:
        raise DomainError(f"multi_process.domains: domain ids must be within {MIN_DOMAIN}..{MAX_DOMAIN} "
                          f"(got {', '.join(f'{r}: {d}' for r, d in bad.items())})")

    used = {d: 0 for d in explicit.values()}
    for d in explicit.values():
        used[d] += 1
    out: dict[str, int] = {}
    domain = first_domain
    for name in names:
        if name in explicit:
            out[name] = explicit[name]
            continue
        while used.get(domain, 0) >= min(robots_per_domain, capacity(domain)):
            domain += 1
            if domain > MAX_DOMAIN:
                auto = n - len(explicit)
                raise DomainError(
                    f"cannot fit {n} robots at {robots_per_domain} per domain from domain "
                    f"{first_domain}: that needs domains {first_domain}..{first_domain + _ceil(auto, robots_per_domain) - 1}"
                    f" but ROS domain ids end at {MAX_DOMAIN} (valid {MIN_DOMAIN}..{MAX_DOMAIN}); "
                    f"raise robots per domain (at most {capacity(0)}) or lower the first domain")
        out[name] = domain
        used[domain] = used.get(domain, 0) + 1

    over = {d: k for d, k in used.items() if k > capacity(d)}
    if over:
        d, k = min(over.items())
        raise DomainError(f"domain {d} would hold {k} robots, but at most {capacity(d)} controller "
                          f"processes fit in it next to the simulator (Fast DDS ports per domain)")
    return out


def _ceil(a: int, b: int) -> int:
    return -(-a // b)


def _span(names: list[str]) -> str:
    return ", ".join(names) if len(names) <= 4 else f"{names[0]} … {names[-1]}"
