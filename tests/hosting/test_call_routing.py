"""The one routing rule of the rounds of calls between places (hosting/calls/rounds.py): which
process (a worker's block, a machine's, a multi-process domain's robots) a call goes to."""
from composed_sim.hosting import RUN_WIDE_ORIGIN, Request, routed
from composed_sim.hosting.calls.between_places import Served
from composed_sim.hosting.calls.rounds import reached

PLACES = [range(0, 4), range(4, 9), range(9, 10)]


def test_a_call_goes_to_the_block_of_its_robot():
    assert [reached(place, PLACES) for place in (0, 3, 4, 8, 9)] == [[0], [0], [1], [1], [2]]


def test_a_call_for_the_run_wide_nodes_goes_to_the_first_place_and_one_for_everyone_to_every_place():
    assert reached(RUN_WIDE_ORIGIN, PLACES) == [0]
    assert reached(None, PLACES) == [0, 1, 2]


def test_a_place_outside_every_block_goes_nowhere():
    assert reached(10, PLACES) == []


def test_places_need_not_be_blocks():
    # multi-process mode: this process (the drones' places 5 and 7), then a domain's robots
    places = [{5, 7}, {0, 1, 2, 3, 4, 6}]
    assert [reached(place, places) for place in (5, 6, 7, RUN_WIDE_ORIGIN)] == [[0], [1], [0], [0]]


def test_shares_go_to_live_places_only_in_the_handovers_order():
    late, early = Request((3, 1), 5, "/s", b""), Request((1, 2), 5, "/s", b"")
    served = Served(())
    shares = routed([late, served, early], PLACES, live=[1, 2])
    assert shares == {1: [served, early, late], 2: [served]}
