"""The multi-threaded executor's rule for robots that answer when published: a tick closes for
such a robot once the executor's threads fell quiet after its callbacks ran and its answer, if
any, was taken. Its callbacks run on the executor's threads while the simulator's thread looks,
so the rule must hold whatever those threads do between the looks."""
from composed_sim.hosting.participant_groups import ParticipantGroups
from composed_sim.hosting.calls.between_places import CallRelay


class Guard:
    """What the callback guard counts: callbacks run so far (in all, per robot) and running now."""

    def __init__(self):
        self.calls, self.running, self.calls_of = 0, 0, {}

    def ran(self, robot):
        self.calls += 1
        self.calls_of[robot] = self.calls_of.get(robot, 0) + 1


class Exchange:
    """Robots that answer when published; the test says who answered."""

    def __init__(self, robots):
        self.open = set(robots)
        self.settled = []

    @property
    def waiting_on_quiet_robots(self):
        return bool(self.open)

    def settle_idle(self, robots):
        done = self.open & set(robots)
        self.open -= done
        self.settled.append(sorted(done))
        return len(done)

    def wait_for_answers(self, timeout_s):
        return not self.open


class SimulatorNode:
    """Its answers are taken while another thread's callback starts: ``on_take`` does that."""

    def __init__(self, on_take):
        self.on_take = on_take

    def take_ready_answers(self):
        self.on_take()
        return 0


def groups_with(guard, exchange, on_take):
    groups = object.__new__(ParticipantGroups)        # only the parts the rule reads
    groups.guard, groups.exchange = guard, exchange
    groups.simulator_nodes = [SimulatorNode(on_take)]
    groups._quiet_robots, groups._settle = True, False
    groups._calls_at_open = {}
    groups.answers_later = []                         # every robot has its cmd_vel publisher
    groups.calls = CallRelay([])                      # no call between places in flight
    groups.remote, groups.run_wide = None, None       # one process, no run-wide node
    return groups


def test_a_robot_whose_callback_starts_after_the_quiet_look_is_not_settled_in_that_round():
    # bot0's callback ran before the look; bot1's starts while the answers are taken (its thread
    # was descheduled until then): its answer may come after the take, so bot1 stays open and
    # bot0 is settled only once a round passes with nothing started.
    guard, exchange = Guard(), Exchange(["bot0", "bot1"])
    guard.ran("bot0")
    published = []

    def on_take():
        if published:                   # the next take gets bot1's answer
            exchange.open.discard(published.pop())
        elif guard.calls_of.get("bot1") is None:
            guard.ran("bot1")           # bot1's callback starts now and publishes after this take
            published.append("bot1")

    groups = groups_with(guard, exchange, on_take)
    assert groups._await_answers(1.0)
    assert exchange.settled == [["bot0"]], exchange.settled       # bot1 answered: never settled


def test_only_robots_that_ran_since_the_tick_opened_are_settled():
    guard, exchange = Guard(), Exchange(["bot0", "bot1"])
    guard.ran("bot1")
    groups = groups_with(guard, exchange, lambda: None)
    groups._calls_at_open = {"bot1": 1}       # bot1's call was of the tick before
    guard.ran("bot0")
    assert not groups._await_answers(0.05)    # bot1 never ran in this tick: it is waited for
    assert exchange.settled[0] == ["bot0"] and exchange.open == {"bot1"}
