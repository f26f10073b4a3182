"""Multi-process mode's controller processes as the simulator knows them: each one's process,
log and start-up pipe, and what it reported there (hosts/multiprocess/hosted_robot.py writes it)."""
from __future__ import annotations

import os
import subprocess
from dataclasses import dataclass, field
from pathlib import Path
from typing import Optional

from composed_sim.hosts.multiprocess.hosted_robot import (FIRST_TIMER_PREFIX, GID_PREFIX, LATER, RUN_WIDE_PREFIX,
                                                        SERVED_PREFIX, TYPE_PREFIX)
from composed_sim.hosting import failure_from_output
from composed_sim.hosts.processes import exit_reason, last_words


@dataclass
class ControllerProcess:
    robot: str
    domain: int
    popen: subprocess.Popen
    log: Path                          # its stdout and stderr
    pipe: Optional[int]                # read end of its start-up pipe, until EOF
    created: bool = False                # its node exists: the CPU-heavy part of start-up is done
    answer_type: Optional[str] = None    # its cmd_vel publisher's type, as "created" reported it
    stopping_since: Optional[float] = None   # monotonic s of the SIGTERM that ends a failed robot
    run_wide_topics: list[str] = field(default_factory=list)   # its run-wide link's, as "created" reported them
    linked: bool = False                 # the simulator's side of its link exists
    topics: Optional[list[str]] = None   # its contract topics, once matched on its side
    gids: list[bytes] = field(default_factory=list)    # its cmd_vel publishers' (cmd_vel_gids)
    served: list[tuple] = field(default_factory=list)  # (name, type) of the services its nodes serve
    answers_later: bool = False          # no cmd_vel publisher yet: quiet until its first answer
    first_timer_tick: int = 0            # … or its timers' first tick
    _buffer: bytes = b""

    def read_pipe(self) -> bool:
        """Read what the child reported ("created type:<type>", then "ready <topics> gid:<hex>…");
        False at EOF."""
        chunk = os.read(self.pipe, 65536)
        self._buffer += chunk
        *lines, self._buffer = self._buffer.split(b"\n")
        for words in (line.decode().split() for line in lines):
            self.created = True
            if words and words[0] == "created":
                self.answer_type = next((w[len(TYPE_PREFIX):] for w in words if w.startswith(TYPE_PREFIX)), None)
                self.answers_later = LATER in words
                self.first_timer_tick = next((int(w[len(FIRST_TIMER_PREFIX):]) for w in words
                                              if w.startswith(FIRST_TIMER_PREFIX)), 0)
                self.run_wide_topics = [w[len(RUN_WIDE_PREFIX):] for w in words if w.startswith(RUN_WIDE_PREFIX)]
            if words and words[0] == "ready":
                self.topics = [w for w in words[1:] if not w.startswith((GID_PREFIX, SERVED_PREFIX))]
                self.gids = [bytes.fromhex(w[len(GID_PREFIX):]) for w in words[1:] if w.startswith(GID_PREFIX)]
                self.served = [tuple(w[len(SERVED_PREFIX):].split("=", 1)) for w in words[1:]
                               if w.startswith(SERVED_PREFIX)]
        return chunk != b""

    def close_pipe(self) -> None:
        if self.pipe is not None:
            os.close(self.pipe)
            self.pipe = None

    def tail(self, chars: int = 2000) -> str:
        try:
            text = self.log.read_text(errors="replace")
        except OSError:
            return ""
        return text[-chars:].strip()


def died_reason(p: ControllerProcess) -> str:
    """How a child ended, with the last line it wrote (a plugin's exception, usually). A child
    whose callback raised says so in a marked line and then ends; one that was stopped in its
    clean-up after that (its time bound, SIGALRM) ended because of the exception, which is named,
    not the line the mark is on."""
    code, tail = p.popen.returncode, p.tail(2000)
    failure = failure_from_output(tail)
    if failure is not None and code != 1:
        error = failure[3].strip().splitlines()[-1:] or [failure[1]]
        return f"{exit_reason(code)} after a callback raised: {error[0]}"
    return exit_reason(code) + last_words(tail[-500:])
