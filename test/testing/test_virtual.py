"""The virtual rigs' second camera of another make (``virtual.coarser``): what it keeps of a
recording's events, on events made up to show each rule alone, and on the real EVK4 recording."""

import numpy as np

from evsync_testing.realdata import read_events
from evsync_testing.virtual import Case, coarser, virtual_rig

MS = 1_000_000


def _events(*rows: tuple[int, int, int, int]) -> tuple[np.ndarray, ...]:
    t, x, y, p = (np.array(col) for col in zip(*rows))
    return t.astype(np.int64), x.astype(np.uint16), y.astype(np.uint16), p.astype(np.uint8)


def test_nothing_asked_keeps_every_event_sorted():
    t, x, y, p = _events((5, 0, 0, 1), (1, 3, 2, 0), (3, 0, 0, 1))
    assert t[coarser(t, x, y, p)].tolist() == [1, 3, 5]


def test_a_higher_threshold_fires_at_the_last_of_each_pixel_s_events_of_one_polarity():
    # pixel (0, 0) on: 10, 20, 30, 40; off: 15, 25; pixel (1, 0) on: 12, 22, 32
    t, x, y, p = _events((10, 0, 0, 1), (20, 0, 0, 1), (30, 0, 0, 1), (40, 0, 0, 1), (15, 0, 0, 0), (25, 0, 0, 0),
                         (12, 1, 0, 1), (22, 1, 0, 1), (32, 1, 0, 1))
    assert t[coarser(t, x, y, p, threshold=2)].tolist() == [20, 22, 25, 40]
    # pooled 2 x 2: (0, 0) and (1, 0) are one pixel, its on events 10, 12, 20, 22, 30, 32, 40
    assert t[coarser(t, x, y, p, pixels=2, threshold=2)].tolist() == [12, 22, 25, 32]


def test_a_refractory_period_drops_the_rest_of_a_burst_at_each_pixel():
    t, x, y, p = _events((0, 0, 0, 1), (400, 0, 0, 1), (900, 0, 0, 1), (2_000, 0, 0, 1), (100, 5, 5, 1))
    # each event within 1000 of the one before at its pixel is dropped; another pixel is not held back
    assert t[coarser(t, x, y, p, dead_ns=1_000)].tolist() == [0, 100, 2_000]


def test_the_second_camera_of_another_make_has_fewer_events_on_the_same_clock(real_data):
    (events,) = read_events(real_data / 'evk4_hd').values()
    plain, _ = virtual_rig(Case('t', 'plain', 'evk4_hd', 'parity', offset_ns=7 * MS), events)
    made, truth = virtual_rig(Case('t', 'make', 'evk4_hd', 'parity', offset_ns=7 * MS, pixels=4, threshold=2,
                                    dead_ns=MS), events)
    assert np.array_equal(plain['/a'], made['/a'])  # the first camera is the recording's, as before
    assert 0.1 * plain['/b'].size < made['/b'].size < 0.5 * plain['/b'].size
    assert set(made['/b'].tolist()) <= set(plain['/b'].tolist())  # events kept, none moved
    assert abs(truth['offset_ns'] - 7 * MS) < 1_000 and truth['skew_ppm'] == 0  # float64 of times near 1e18
