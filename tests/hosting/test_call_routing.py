"""The one routing rule of the rounds of calls between places (hosting/calls/between_places.py):
which block of robots (a worker's, a machine's) a call goes to."""
from composed_sim.hosting import RUN_WIDE_ORIGIN, blocks_reached

BLOCKS = [(0, 4), (4, 9), (9, 10)]


def test_a_call_goes_to_the_block_of_its_robot():
    assert [blocks_reached(place, BLOCKS) for place in (0, 3, 4, 8, 9)] == [[0], [0], [1], [1], [2]]


def test_a_call_for_the_run_wide_nodes_goes_to_the_first_block_and_one_for_everyone_to_every_block():
    assert blocks_reached(RUN_WIDE_ORIGIN, BLOCKS) == [0]
    assert blocks_reached(None, BLOCKS) == [0, 1, 2]


def test_a_place_outside_every_block_goes_nowhere():
    assert blocks_reached(10, BLOCKS) == []
