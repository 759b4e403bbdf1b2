"""The stamp synchroniser, without ROS: exact and approximate matching, arrival orders,
dropped and duplicate stamps, time jumps."""
import itertools

import numpy as np
import pytest

from fcop_ros.sync import StampSynchronizer

MS = 1_000_000


def run(sync, events):
    """Feed (input, stamp) events; return the emitted sets as lists of (input, stamp) tags."""
    out = []
    for i, stamp in events:
        for _, msgs in sync.add(i, stamp, (i, stamp)):
            out.append(msgs)
    return out


def check_invariants(sets, n):
    used = set()
    last = None
    for msgs in sets:
        assert [m[0] for m in msgs] == list(range(n))
        for m in msgs:
            assert m not in used  # each message at most once
            used.add(m)
        top = max(m[1] for m in msgs)
        assert last is None or min(m[1] for m in msgs) > last  # stamp order
        last = top


def test_exact_all_arrival_orders_within_a_frame():
    """Whatever order the three topics of each frame arrive in, every frame is matched."""
    rng = np.random.default_rng(0)
    for trial in range(200):
        events = []
        for k in range(20):
            order = rng.permutation(3)
            events += [(int(i), k * 33 * MS) for i in order]
        sync = StampSynchronizer(3, queue_size=3)
        sets = run(sync, events)
        check_invariants(sets, 3)
        assert len(sets) == 20 and sync.stats.dropped_total == 0
        assert all(len({m[1] for m in s}) == 1 for s in sets)


def test_exact_with_lag_between_topics():
    """One topic lags by up to queue_size-1 frames: still everything matches."""
    events = []
    for k in range(12):
        events += [(0, k * MS), (1, k * MS)]
        if k >= 3:
            events.append((2, (k - 3) * MS))
    sync = StampSynchronizer(3, queue_size=5)
    sets = run(sync, events)
    check_invariants(sets, 3)
    assert len(sets) == 9 and sync.stats.dropped_total == 0


def test_globally_shuffled_arrival_accounts_for_every_message():
    rng = np.random.default_rng(1)
    for trial in range(300):
        n_frames = int(rng.integers(1, 15))
        events = [(i, k * 10 * MS) for k in range(n_frames) for i in range(3)]
        rng.shuffle(events)
        sync = StampSynchronizer(3, queue_size=int(rng.integers(1, 6)))
        sets = run(sync, events)
        check_invariants(sets, 3)
        # Every message is matched once, dropped once (counted) or still pending.
        assert 3 * len(sets) + sync.stats.dropped_total + sync.pending() == 3 * n_frames
        assert sync.stats.matched == len(sets)


def test_dropped_and_duplicate_stamps():
    sync = StampSynchronizer(3, queue_size=10)
    events = [(0, 1 * MS), (1, 1 * MS), (2, 1 * MS),   # frame 1
              (0, 2 * MS), (1, 2 * MS),                # frame 2 loses its mask
              (0, 3 * MS), (0, 3 * MS),                # duplicate depth
              (1, 3 * MS), (2, 3 * MS)]
    sets = run(sync, events)
    assert [s[0][1] for s in sets] == [1 * MS, 3 * MS]
    assert sync.stats.dropped["duplicate"] == 1
    assert sync.stats.dropped["unmatched"] == 2  # depth and nocs of frame 2
    assert sync.pending() == 0


def test_approximate_matching_with_slop():
    rng = np.random.default_rng(2)
    sync = StampSynchronizer(3, queue_size=5, slop=0.005)
    events = []
    for k in range(50):
        base = k * 33 * MS
        jitter = rng.integers(-2 * MS, 2 * MS, 3)
        tags = [(i, int(base + jitter[i])) for i in range(3)]
        rng.shuffle(tags)
        events += tags
    sets = run(sync, events)
    check_invariants(sets, 3)
    assert len(sets) == 50
    for s in sets:
        stamps = [m[1] for m in s]
        assert max(stamps) - min(stamps) <= 5 * MS
    exact = StampSynchronizer(3, queue_size=5)
    assert len(run(exact, events)) < 5  # the same stream does not match exactly


def test_approximate_rejects_beyond_slop():
    sync = StampSynchronizer(2, queue_size=5, slop=0.001)
    sets = run(sync, [(0, 0), (1, 3 * MS), (0, 3 * MS + 500_000)])
    assert len(sets) == 1 and sets[0] == [(0, 3 * MS + 500_000), (1, 3 * MS)]
    assert sync.stats.dropped["unmatched"] == 1


def test_late_message_and_time_jump_reset():
    sync = StampSynchronizer(2, queue_size=5, reset_after=1.0)
    run(sync, [(0, 5000 * MS), (1, 5000 * MS)])
    assert run(sync, [(0, 4900 * MS)]) == [] and sync.stats.dropped["late"] == 1
    run(sync, [(0, 5100 * MS)])
    # A jump back by more than reset_after: a looped bag starts over.
    sets = run(sync, [(0, 10 * MS), (1, 10 * MS)])
    assert sync.stats.resets == 1 and len(sets) == 1
    assert sync.stats.dropped["time_jump_reset"] == 1  # the pending 5100 ms depth


def test_queue_bound_and_bad_arguments():
    sync = StampSynchronizer(3, queue_size=4)
    run(sync, [(0, k * MS) for k in range(10)])
    assert sync.pending() == 4 and sync.stats.dropped["queue_full"] == 6
    for bad in [dict(n_inputs=0), dict(n_inputs=3, queue_size=0), dict(n_inputs=3, slop=-1.0)]:
        with pytest.raises(ValueError):
            StampSynchronizer(**bad)


@pytest.mark.parametrize("perm", list(itertools.permutations(range(3))))
def test_each_permutation_of_one_frame(perm):
    sync = StampSynchronizer(3)
    sets = run(sync, [(i, 7) for i in perm])
    assert len(sets) == 1 and sets[0] == [(0, 7), (1, 7), (2, 7)]
