"""Playing a bag to a running identifier node at the node's pace (shared by the node tests)."""

import math
import time

from ship_ident.commands.play import Player
from ship_ident.ros.node import TICKS_PER_REFIT

LAST_REFIT_TIMEOUT = 120.0  # s of wall time for the node to catch up with the clock
REFIT_PERIOD = 5.0  # s, the node's default
# s: /clock at most a refit period and a tick and a half past the node's newest record, so the next
# refit (due a period on, started at the first tick past it) is published before the one after it is
# due: a refit due while the previous one still runs would be skipped and the record flagged
# refit_overran (WARN, nothing trusted), which on a loaded machine is every record; a refit due as the
# previous one returns from its publish is still skipped, and the node stalls: the lead then grows by a
# period (``Listener.pace_by_node``)
PLAY_LEAD = REFIT_PERIOD + 1.5 * REFIT_PERIOD / TICKS_PER_REFIT


def play_to_the_end(listener, samples, rate, lead=PLAY_LEAD) -> None:
    """Play ``samples`` to the node ``listener`` hears at up to ``rate`` x real time (a float, or
    (stamp s, rate) pairs: each rate from its stamp on), then wait until
    the node has published its refit of the bag's end (one a refit period from it at least). The
    pace is the node's, not the machine's: /clock never runs more than ``lead`` s past the node's
    newest record (``Listener.pace_by_node``), so a node that compiles its kernels in its first
    refit, or is starved of CPU, slows the play instead of missing it. Fails saying how far the
    node got."""
    player = Player(listener.node)
    assert player.wait_for_subscribers(20.0)
    hold = listener.pace_by_node(lead, LAST_REFIT_TIMEOUT, skipped=REFIT_PERIOD, clock=player.republish_clock)
    rates = ((samples[0].time, rate),) if isinstance(rate, (int, float)) else tuple(rate)
    for (begin, part_rate), (end, _) in zip(rates, (*rates[1:], (math.inf, None))):
        part = [s for s in samples if begin <= s.time < end]
        if part:
            player.play(part, part_rate, hold=hold)
    end = samples[-1].time

    def caught_up():
        return bool(listener.estimates) and listener.estimates[-1]["stamp"] >= end - REFIT_PERIOD

    deadline = time.monotonic() + LAST_REFIT_TIMEOUT
    reached = caught_up()
    while not reached and time.monotonic() < deadline:  # the last /clock sent again: the node takes it best effort
        reached = listener.spin(1.0, caught_up)
        player.republish_clock()
    assert reached, (
        f"the node's newest refit is at {listener.newest_refit()} s of the bag's {end:g} s "
        f"after {LAST_REFIT_TIMEOUT:g} s"
    )
