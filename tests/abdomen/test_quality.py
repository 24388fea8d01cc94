"""Tissue-quality accumulation against hand sums."""

from __future__ import annotations

import math

import pytest

from vasim.abdomen.quality import TissueQuality


def test_integrals_counts_and_maxima():
    q = TissueQuality()
    dt = 0.004
    steps = [  # (|F| along x, |tau| along z, contact, delicate, displacement)
        (0.0, 0.0, False, False, 0.0),
        (3.0, 0.1, True, False, 0.001),
        (4.0, 0.2, True, True, 0.003),
        (0.0, 0.0, False, False, 0.002),
        (2.0, 0.0, True, True, 0.0),
    ]
    for f, tau, c, d, disp in steps:
        q.add(dt, force=(f, 0.0, 0.0), torque=(0.0, 0.0, tau), in_contact=c,
              delicate_contact=d, target_displacement=disp)
    assert q.contact_count == 2 and q.delicate_count == 2
    assert q.contact_time == pytest.approx(3 * dt)
    assert q.delicate_time == pytest.approx(2 * dt)
    assert q.force_integral == pytest.approx(9.0 * dt)
    assert q.torque_integral == pytest.approx(0.3 * dt)
    assert q.max_force == 4.0
    assert q.target_displacement_max == 0.003
    assert q.target_displacement_mean == pytest.approx(0.006 / 5)
    assert set(q.as_dict()) >= {"contact_time", "force_integral", "delicate_count"}
    assert not any(k.startswith("_") for k in q.as_dict())


def test_a_non_finite_step_is_not_accumulated():
    q = TissueQuality()
    q.add(0.004, force=(math.nan, 0, 0), torque=(0, 0, 0), in_contact=True)
    assert q.duration == 0 and q.contact_count == 0 and q.force_integral == 0
