"""Test skeleton for an AE method plugin: copy beside your method and run ``pytest``.

Each test states a property the method must have on a synthetic mosaic (uint16, 12-bit),
so it runs without data.  Then run the method in closed loop on a recording:
``exposim run SEQ --methods all,my_ae:MyAE -o OUT`` (with ``my_ae`` importable).
"""

import math

import numpy as np

from my_ae import MyAE


def flat(dn, shape=(32, 48)):
    return np.full(shape, dn, dtype=np.uint16)


def test_fixed_point_keeps_the_exposure():
    # A frame already at the target (40 % of 4095 DN = 1638 DN) keeps its exposure.
    assert math.isclose(MyAE(target=0.4).next_exposure(flat(1638), 5.0), 5.0, rel_tol=1e-12)


def test_twice_as_bright_halves_the_exposure():
    ae = MyAE(target=0.4)
    assert math.isclose(ae.next_exposure(flat(3276), 8.0), 4.0, rel_tol=1e-12)


def test_black_frame_gives_a_finite_positive_exposure():
    t = MyAE().next_exposure(flat(0), 1.0)
    assert math.isfinite(t) and t > 0


def test_reset_then_same_answer():
    ae = MyAE()
    first = ae.next_exposure(flat(1000), 3.0)
    ae.reset()
    assert ae.next_exposure(flat(1000), 3.0) == first
